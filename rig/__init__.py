"""spectral-rig: the user's side — CLI, capture sessions, calibration wizard, reports."""

__version__ = "0.1.0"
