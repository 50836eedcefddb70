"""Frames in: RAW (or linear TIFF/NPY) decoded to linear camera RGB, ambient light subtracted."""
