"""What every reconstruction stage runs on: resumable, timed stage runs (hloc's habit: files
in, files out, skipped when done), peak memory, progress bars, and the all-or-nothing
publication of ``recon/``. It imports no stage, so every stage may import it."""
