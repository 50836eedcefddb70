"""Colour charts in captured frames: detection (:mod:`.detect`), per-patch linear camera RGB
(:mod:`.patches`) and the session's chart check (:mod:`.check`)."""

from reconstruct.chart.patches import ChartPatches, read_patches, read_patches_linear

__all__ = ["ChartPatches", "read_patches", "read_patches_linear"]
