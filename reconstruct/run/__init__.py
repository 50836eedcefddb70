"""The run itself: the pipeline and its front, resumable stages, status, log, progress,
peak memory and the all-or-nothing publication of ``recon/``."""
