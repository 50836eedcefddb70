"""The per-view board check: is enough of the printed board in the frame for a pose?

It runs on every view's first lit frame while the person waits, so it must be cheap: the grey
look is built from the Bayer mosaic the decode check already holds (white-balanced, binned,
LibRaw's BT.709 curve, no auto-brightening, so the paper/ink contrast tells about the
exposure), and the board is first searched in an image binned 2x further; only when that
finds too few corners is the full-size look searched too, so a view is never reported
with fewer corners than the full-size look would give it."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from reconstruct.poses.board import BoardSpec, board_visibility_report, linear_to_u8
from rig.capture.frames import RawData

LARGE_SENSOR_PX = 2000  # wider frames get a half-size full look (as LibRaw's half_size)


@dataclass(frozen=True)
class BoardLook:
    """Corners found and paper/ink contrast, in a look binned by ``binning``."""

    corners: int
    contrast: float
    binning: int


def board_binnings(raw: RawData) -> tuple[int, int]:
    """(quick, full) binning factors of the two looks; multiples of the CFA period so every
    bin holds the same mix of colour filters."""
    period = max(raw.period, 2)
    full = period if raw.values.shape[1] > LARGE_SENSOR_PX else 1
    return (2 * full if full > 1 else period), full


def board_image(raw: RawData, binning: int = 1) -> np.ndarray:
    """An 8-bit grey look at a frame, ``binning`` x ``binning`` pixels per output pixel.

    Mosaics: white-balanced and clipped per filter (as LibRaw scales), averaged over each bin,
    or at full size over a sliding CFA period (one of each filter everywhere), then LibRaw's
    default BT.709 curve. Demosaiced/monochrome linear frames (TIFF, NumPy) go through
    :func:`reconstruct.poses.board.linear_to_u8`."""
    if raw.cfa_gain is None or raw.cfa_black is None:
        span = max(raw.white - raw.black, 1e-12)
        linear = (raw.values.astype(np.float32) - np.float32(raw.black)) / np.float32(span)
        if linear.ndim == 3:
            linear = linear.mean(axis=2)
        return linear_to_u8(_bin(linear, binning))
    period = raw.period
    black = raw.cfa_black.astype(np.float32)
    gain = raw.cfa_gain.astype(np.float32)
    if binning == 1:
        h, w = (np.asarray(raw.values.shape[:2]) // period) * period
        tiles = raw.values[:h, :w].astype(np.float32).reshape(h // period, period, -1, period)
        linear = np.clip((tiles - black[None, :, None]) * gain[None, :, None], 0.0, 1.0)
        return _bt709_u8(cv2.blur(linear.reshape(h, w), (period, period)))
    if binning % period:
        raise ValueError(f"binning {binning} is no multiple of the CFA period {period}")
    # Binned: average each filter's plane first (on the integers: a few ms even at 21 MP),
    # then scale the small planes.
    h, w = (np.asarray(raw.values.shape[:2]) // binning) * binning
    grey = np.zeros((h // binning, w // binning), np.float32)
    for i in range(period):
        for j in range(period):
            plane = np.ascontiguousarray(raw.values[i:h:period, j:w:period])
            plane = _bin(plane, binning // period)
            grey += np.clip((plane - black[i, j]) * gain[i, j], 0.0, 1.0)
    return _bt709_u8(grey / period**2)


def _bin(image: np.ndarray, factor: int) -> np.ndarray:
    """Mean of each ``factor`` x ``factor`` block as float32 (OpenCV's area resampling at an
    integer factor, several times faster than a NumPy reshape-mean; uint16 stays integer
    inside it, so a 21 MP plane bins without a float copy)."""
    if factor == 1:
        return image.astype(np.float32)
    h, w = image.shape[0] // factor, image.shape[1] // factor
    block = np.ascontiguousarray(image[: h * factor, : w * factor])
    if block.dtype not in (np.uint8, np.uint16, np.float32):
        block = block.astype(np.float32)
    binned = cv2.resize(block, (w, h), interpolation=cv2.INTER_AREA)
    return np.asarray(binned, dtype=np.float32)


@functools.cache
def _bt709_table(size: int = 4096) -> np.ndarray:
    x = np.linspace(0.0, 1.0, size)
    curve = np.where(x < 0.018, 4.5 * x, 1.099 * x**0.45 - 0.099)
    return np.round(255.0 * curve).astype(np.uint8)


def _bt709_u8(linear: np.ndarray) -> np.ndarray:
    """LibRaw's default output curve (BT.709: power 0.45, toe slope 4.5) to 8 bits."""
    table = _bt709_table()
    index = np.clip(linear * (table.size - 1) + 0.5, 0, table.size - 1).astype(np.intp)
    return table[index]


def look_for_board(raw: RawData, spec: BoardSpec, min_corners: int) -> BoardLook:
    """Corners and contrast from the quick look, or from the full-size one when the quick
    look finds fewer than ``min_corners`` (whichever finds more)."""
    quick, full = board_binnings(raw)
    best = BoardLook(*board_visibility_report(board_image(raw, quick), spec), quick)
    if best.corners < min_corners and full != quick:
        again = BoardLook(*board_visibility_report(board_image(raw, full), spec), full)
        best = again if again.corners >= best.corners else best
    return best
