"""Camera drivers: tethered (gphoto2), folder-watch, and hand-held import."""
