"""Structured-light and flat-field images for a projector, as pure functions returning arrays.

Gray code (binary-reflected) stripes for columns and rows, each bit with its inverse so a
pixel's bit is decided by comparing the two captures (robust to albedo and ambient light);
bit 0 is the most significant. ``decode_gray_code`` inverts the sequence.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

AXES = ("col", "row")


def bit_count(size: int) -> int:
    """Bits needed to give each of ``size`` columns (or rows) its own code."""
    if size < 1:
        raise ValueError(f"size must be >= 1, got {size}")
    return max(1, int(np.ceil(np.log2(size))))


def gray_encode(values: np.ndarray) -> np.ndarray:
    return values ^ (values >> 1)


def gray_decode(codes: np.ndarray) -> np.ndarray:
    out = codes.copy()
    shift = codes >> 1
    while np.any(shift):
        out ^= shift
        shift = shift >> 1
    return out


def pattern_id(axis: str, bit: int, inverse: bool) -> str:
    return f"gray-{axis}-{bit:02d}" + ("-inv" if inverse else "")


def gray_code_image(
    width: int, height: int, axis: str, bit: int, inverse: bool = False
) -> np.ndarray:
    """(height, width) uint8 image, 255 where the bit (MSB = bit 0) of the Gray code is set."""
    if axis not in AXES:
        raise ValueError(f"axis must be one of {AXES}, got {axis!r}")
    size = width if axis == "col" else height
    bits = bit_count(size)
    if not 0 <= bit < bits:
        raise ValueError(f"bit {bit} outside 0..{bits - 1} for size {size}")
    codes = gray_encode(np.arange(size, dtype=np.int64))
    stripe = ((codes >> (bits - 1 - bit)) & 1).astype(bool) ^ inverse
    line = np.where(stripe, 255, 0).astype(np.uint8)
    if axis == "col":
        return np.broadcast_to(line[None, :], (height, width)).copy()
    return np.broadcast_to(line[:, None], (height, width)).copy()


def gray_code_sequence(width: int, height: int) -> list[tuple[str, np.ndarray]]:
    """All patterns: for columns then rows, each bit MSB first, followed by its inverse."""
    out = []
    for axis, size in (("col", width), ("row", height)):
        for bit in range(bit_count(size)):
            for inverse in (False, True):
                out.append(
                    (
                        pattern_id(axis, bit, inverse),
                        gray_code_image(width, height, axis, bit, inverse),
                    )
                )
    return out


def decode_gray_code(
    captures: Mapping[str, np.ndarray], width: int, height: int, min_contrast: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Projector (column, row) seen by each camera pixel, and a validity mask.

    ``captures`` maps pattern ids to camera images (same shape; colour is averaged). A pixel is
    valid where every pattern/inverse pair differs by more than ``min_contrast`` and the code
    falls inside the projector.
    """
    result = []
    valid: np.ndarray | None = None
    for axis, size in (("col", width), ("row", height)):
        codes: np.ndarray | None = None
        for bit in range(bit_count(size)):
            on = _gray(captures[pattern_id(axis, bit, False)])
            off = _gray(captures[pattern_id(axis, bit, True)])
            if codes is None:
                codes = np.zeros(on.shape, dtype=np.int64)
                valid = np.ones(on.shape, dtype=bool) if valid is None else valid
            codes = (codes << 1) | (on > off)
            valid = valid & (np.abs(on - off) > min_contrast)
        assert codes is not None and valid is not None
        index = gray_decode(codes)
        valid &= index < size
        result.append(index)
    assert valid is not None
    return result[0], result[1], valid


def _gray(image: np.ndarray) -> np.ndarray:
    data = np.asarray(image, dtype=np.float64)
    return data.mean(axis=-1) if data.ndim == 3 else data


def uniform_image(width: int, height: int, rgb: Sequence[float] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """(height, width, 3) float image of one colour in [0, 1] (flat-field illumination)."""
    colour = np.asarray(rgb, dtype=np.float64)
    if colour.shape != (3,) or np.any((colour < 0) | (colour > 1)):
        raise ValueError(f"rgb must be three values in [0, 1], got {list(rgb)}")
    return np.broadcast_to(colour, (height, width, 3)).copy()
