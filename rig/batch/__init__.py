"""`rig batch`: many sessions reconstructed on a Dask cluster, one task per session."""
