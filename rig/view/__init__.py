"""`rig view`: a reconstruction's per-vertex spectra in the browser (plotly, offline)."""
