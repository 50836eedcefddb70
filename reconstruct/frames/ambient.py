"""Room-light (ambient) subtraction: a view's ``ambient`` frame (``core.labels.AMBIENT``, bulb
off) holds what the room adds to every lit frame of that view, so lit − ambient (scaled to the
lit frame's exposure, in linear camera units) is what the bulb alone lit — the forward model's
image.

The difference is noisier than a frame taken in the dark: the variances of both frames add.
With shot noise (variance ∝ signal) a lit frame holding bulb signal b and room signal a has
variance ∝ b + a, the ambient frame scaled by the exposure ratio ρ adds ρ·a, against b for a
dark-room frame, so the frame's observations are weighted by ``sqrt(b / (b + (1 + ρ) a))``
(frame means over its valid pixels; read noise is left out). A pixel is usable only where
neither frame saturated.

Hand-held captures move between frames: the ambient frame is checked for alignment with the
lit frame by phase correlation of their log-image gradients (shading-free edges: silhouette
and texture) on a downsampled copy. Past ``max_shift_px`` a per-pixel difference would paint
edges into the reflectance, so that view falls back to subtracting one robust per-channel
level (the median room light over the bulb-lit object) and its weight is halved for the
spatial variation of the room light the level misses; a warning names the view.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

log = logging.getLogger(__name__)
ALIGN_SIDE = 256  # longest side (px) of the copies the alignment check correlates
FALLBACK_WEIGHT = 0.5


@dataclass
class Subtracted:
    """A lit frame with the room light taken out."""

    image: np.ndarray  # (H, W, 3) float32, linear units of the lit frame
    valid: np.ndarray  # (H, W) bool: neither frame saturated
    weight: float  # relative 1/std of the frame's observations (1 = dark room)
    shift_px: float  # measured lit↔ambient misalignment, full-resolution pixels
    aligned: bool


def exposure_ratio(
    lit_exposure_s: float, lit_iso: float, amb_exposure_s: float, amb_iso: float
) -> float:
    """Factor that brings the ambient frame to the lit frame's exposure (linear raw units)."""
    return float(lit_exposure_s * lit_iso) / float(amb_exposure_s * amb_iso)


def _edges(image: np.ndarray, scale: float) -> np.ndarray:
    """Gradient magnitude of the log grey image, downsampled by ``scale`` (≤ 1)."""
    grey = np.asarray(image, dtype=np.float32).mean(axis=2)
    if scale < 1.0:
        size = (max(8, round(grey.shape[1] * scale)), max(8, round(grey.shape[0] * scale)))
        grey = cv2.resize(grey, size, interpolation=cv2.INTER_AREA)
    floor = max(float(np.percentile(grey, 99)) * 1e-2, 1e-6)
    log_grey = np.log(np.maximum(grey, 0.0) + floor)
    gx = cv2.Sobel(log_grey, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(log_grey, cv2.CV_32F, 0, 1, ksize=3)
    return np.hypot(gx, gy).astype(np.float64)


def misalignment_px(lit: np.ndarray, ambient: np.ndarray) -> float:
    """Translation (full-resolution pixels) between the two frames' log-gradient images."""
    h, w = lit.shape[:2]
    scale = min(1.0, ALIGN_SIDE / max(h, w))
    a, b = _edges(lit, scale), _edges(ambient, scale)
    window = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_64F)
    (dx, dy), _ = cv2.phaseCorrelate(a, b, window)
    return float(np.hypot(dx, dy) / scale)


def noise_weight(bulb: np.ndarray, room: np.ndarray, valid: np.ndarray, ratio: float) -> float:
    """``sqrt(b / (b + (1 + ρ) a))`` from the frame means of bulb and room signal."""
    if not valid.any():
        return 1.0
    b = max(float(np.mean(bulb[valid])), 0.0)
    a = max(float(np.mean(room[valid])), 0.0)
    if b + a <= 0.0:
        return 1.0
    return float(np.sqrt(b / (b + (1.0 + ratio) * a)))


def subtract_ambient(
    lit: np.ndarray,
    lit_valid: np.ndarray,
    ambient: np.ndarray,
    ambient_valid: np.ndarray,
    ratio: float,
    name: str,
    max_shift_px: float = 1.0,
) -> Subtracted:
    """Lit frame minus the exposure-scaled ambient frame, with the fallback for a moved camera
    (module docstring); ``name`` (e.g. ``view 3 LED1``) goes into the warning."""
    room = np.asarray(ambient, dtype=np.float32) * np.float32(ratio)
    shift = misalignment_px(lit, room)
    if shift <= max_shift_px:
        valid = lit_valid & ambient_valid
        image = lit - room
        weight = noise_weight(image, room, valid, ratio)
        return Subtracted(image.astype(np.float32), valid, weight, shift, True)
    grey = lit.mean(axis=2)
    bright = lit_valid & ambient_valid & (grey >= np.percentile(grey, 75))
    level = np.median(room[bright], axis=0) if bright.any() else np.zeros(3, np.float32)
    image = (lit - level.astype(np.float32)).astype(np.float32)
    weight = FALLBACK_WEIGHT * noise_weight(
        image, np.broadcast_to(level, lit.shape), lit_valid, ratio
    )
    log.warning(
        "%s: the ambient frame is %.1f px off the lit frame (hand-held?): subtracting a "
        "per-channel room level %s instead of the frame, and down-weighting the view; hold "
        "the camera still (tripod) between the ambient and lit frames",
        name,
        shift,
        np.array2string(level, precision=4),
    )
    return Subtracted(image, lit_valid.copy(), weight, shift, False)
