"""The white reference's colour in a RAW frame, read straight from the CFA."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.errors import RigError

REGION_FRACTION = 0.02  # default reference region: a central square this fraction of the image


def region_rgb(path: Path, region: tuple[int, int, int, int] | None) -> tuple[np.ndarray, bool]:
    """Mean of each CFA colour (R, G, B) in ``region`` of a RAW frame, in (raw − black) /
    (white − black), and whether any pixel there is saturated (no demosaicing needed)."""
    from reconstruct.frames.raw import read_mosaic

    mosaic = read_mosaic(path)
    height, width = mosaic.values.shape
    if region is None:
        side = max(4, int(REGION_FRACTION * min(height, width)) // 2 * 2)
        region = (
            (width - side) // 2,
            (height - side) // 2,
            (width + side) // 2,
            (height + side) // 2,
        )
    x0, y0, x1, y1 = region
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise RigError(
            f"--reference-region {region} is outside the {width}x{height} image",
            "give X0,Y0,X1,Y1 inside the image",
        )
    window = (slice(y0, y1), slice(x0, x1))
    level = mosaic.levels(window, np.float64)
    letters = np.array(list(mosaic.colour_desc))[mosaic.colours[window]]
    rgb = np.array([level[letters == c].mean() for c in "RGB"])
    return rgb, bool(np.any(mosaic.values[window] >= mosaic.white))
