"""Spectra: grid, calibration store, spectral basis, 2-D reflectance estimation, illumination
selection. A library: it touches no device and imports no other spectral-rig package."""
