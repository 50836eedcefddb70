"""Binary-reflected Gray code as pure bit math: neighbouring columns (or rows) differ in one
bit, so a stripe edge blurred by the optics corrupts one bit of one code, never many. Bit 0 is
the most significant: it splits the projector in half."""

from __future__ import annotations

import numpy as np


def bit_count(size: int) -> int:
    """Bits needed to give each of ``size`` columns (or rows) its own code."""
    if size < 1:
        raise ValueError(f"size must be >= 1, got {size}")
    return max(1, int(np.ceil(np.log2(size))))


def gray_encode(values: np.ndarray) -> np.ndarray:
    """Gray code of non-negative integers: ``v ^ (v >> 1)``."""
    return values ^ (values >> 1)


def gray_decode(codes: np.ndarray) -> np.ndarray:
    """Inverse of :func:`gray_encode` for non-negative int64 codes, vectorised (prefix XOR by
    doubling shifts: six passes for any code width)."""
    out = codes.copy()
    shift = 1
    while shift < 64:
        out ^= out >> shift
        shift *= 2
    return out


def stripe(size: int, bit: int) -> np.ndarray:
    """(size,) bool: bit ``bit`` (0 = most significant) of each index's Gray code."""
    bits = bit_count(size)
    if not 0 <= bit < bits:
        raise ValueError(f"bit {bit} outside 0..{bits - 1} for size {size}")
    codes = gray_encode(np.arange(size, dtype=np.int64))
    return ((codes >> (bits - 1 - bit)) & 1).astype(bool)
