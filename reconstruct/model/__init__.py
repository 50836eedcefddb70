"""The image-formation model every stage shares: cameras and poses (COLMAP conventions), the
forward model, rendering and Embree ray casting."""
