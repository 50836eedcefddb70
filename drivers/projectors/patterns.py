"""Structured-light and flat-field images for a projector, as pure functions returning arrays.

Gray code (binary-reflected, :mod:`core.graycode`) stripes for columns and rows, each bit with
its inverse so a pixel's bit is decided by comparing the two captures (robust to albedo and
ambient light); bit 0 is the most significant. Frames are named as :mod:`core.labels` says;
``reconstruct.initial_mesh.structured_light`` decodes them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from core.graycode import bit_count, stripe
from core.labels import AXES, pattern_label


def gray_code_image(
    width: int, height: int, axis: str, bit: int, inverse: bool = False
) -> np.ndarray:
    """(height, width) uint8 image, 255 where the bit (MSB = bit 0) of the Gray code is set."""
    if axis not in AXES:
        raise ValueError(f"axis must be one of {AXES}, got {axis!r}")
    line = np.where(stripe(width if axis == "col" else height, bit) ^ inverse, 255, 0)
    line = line.astype(np.uint8)
    if axis == "col":
        return np.broadcast_to(line[None, :], (height, width)).copy()
    return np.broadcast_to(line[:, None], (height, width)).copy()


def gray_code_sequence(width: int, height: int) -> list[tuple[str, np.ndarray]]:
    """All patterns: for columns then rows, each bit MSB first, followed by its inverse."""
    out = []
    for axis, size in zip(AXES, (width, height), strict=True):
        for bit in range(bit_count(size)):
            for inverse in (False, True):
                image = gray_code_image(width, height, axis, bit, inverse)
                out.append((pattern_label(axis, bit, inverse), image))
    return out


def uniform_image(width: int, height: int, rgb: Sequence[float] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """(height, width, 3) float image of one colour in [0, 1] (flat-field illumination)."""
    colour = np.asarray(rgb, dtype=np.float64)
    if colour.shape != (3,) or np.any((colour < 0) | (colour > 1)):
        raise ValueError(f"rgb must be three values in [0, 1], got {list(rgb)}")
    return np.broadcast_to(colour, (height, width, 3)).copy()
