"""Spectrometer drivers: seabreeze (Ocean) and vendor-file import."""
