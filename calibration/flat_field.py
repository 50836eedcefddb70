"""Flat field: the lens's fall-off towards the corners as a smooth per-channel gain map.

The model is lensfun's vignetting polynomial, one per colour channel::

    g(r) = 1 + k1 r² + k2 r⁴ + k3 r⁶,   r = |pixel − centre| / half-diagonal

so the gain is 1 at the optical centre (the radiometric scale the wizard measures there stays
valid) and the map depends on the image size only through its aspect ratio. A low order keeps
card texture, dust and noise out of it. Decoding divides linear camera RGB by ``g``.

It is fitted to frames of a diffuse white card filling the frame under the rig's own light,
divided first by the irradiance the light itself gives the card (:func:`card_shading`: a near
point light makes a flat card darker towards its edges too, which the forward model already
accounts for), or taken from a lensfun profile (:mod:`calibration.lensfun`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from core.errors import RigError

FORMAT = "spectral-rig-flat-field/1"
ORDER = 3  # terms in r², r⁴, r⁶ (lensfun's "pa" model)
BLOCK_PX = 8  # frames are averaged over blocks of this side before fitting
CLIP_SIGMA = 3.0  # blocks further than this from the first fit (dust, a label) are dropped
ASPECT_TOLERANCE = 0.01


@dataclass(frozen=True)
class FlatField:
    """A fitted flat field: ``coefficients`` (3, ORDER) per channel R, G, B; ``centre`` the
    optical centre as a fraction of (width, height); ``aspect`` width / height of the images
    it was fitted on; ``method`` and ``details`` say how it was made."""

    coefficients: np.ndarray
    aspect: float
    centre: tuple[float, float] = (0.5, 0.5)
    method: str = "white card"
    details: Mapping[str, Any] = field(default_factory=dict)

    def gain(self, width: int, height: int, where: str = "flat field") -> np.ndarray:
        """The gain map (height, width, 3) at pixel centres; 1 at the optical centre."""
        if abs(width / height - self.aspect) > ASPECT_TOLERANCE * self.aspect:
            raise RigError(
                f"{where} was made for images of aspect {self.aspect:.4g}, the frames are "
                f"{width}x{height}",
                "make a flat field with this camera's image size (`rig calibrate flat-field`)",
            )
        r2 = _radius2(width, height, self.centre)
        powers = np.stack([r2 ** (k + 1) for k in range(ORDER)], axis=-1)  # (H, W, ORDER)
        return (1.0 + powers @ self.coefficients.T).astype(np.float32)

    def corner_gain(self) -> np.ndarray:
        """The gain at r = 1 (the corners) per channel."""
        return 1.0 + self.coefficients.sum(axis=1)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "model": "g(r) = 1 + k1 r^2 + k2 r^4 + k3 r^6, r = 1 at half the diagonal",
            "method": self.method,
            "aspect": float(self.aspect),
            "centre": [float(c) for c in self.centre],
            "coefficients": {
                c: [float(k) for k in row] for c, row in zip("RGB", self.coefficients, strict=True)
            },
            "corner_gain": {
                c: round(float(g), 5) for c, g in zip("RGB", self.corner_gain(), strict=True)
            },
            "details": dict(self.details),
        }

    @classmethod
    def from_dict(cls, data: Any, where: str) -> FlatField:
        fix = "make it again with `rig calibrate flat-field` (or the wizard)"
        if not isinstance(data, Mapping) or data.get("format") != FORMAT:
            raise RigError(f"{where} is not a flat field ({FORMAT})", fix)
        try:
            coefficients = np.array(
                [[float(k) for k in data["coefficients"][c]] for c in "RGB"], dtype=float
            )
            centre = tuple(float(c) for c in data["centre"])
            aspect = float(data["aspect"])
        except (KeyError, TypeError, ValueError) as error:
            raise RigError(f"{where}: malformed flat field ({error})", fix) from error
        if coefficients.shape != (3, ORDER) or len(centre) != 2 or not aspect > 0:
            raise RigError(f"{where}: malformed flat field (shape or aspect)", fix)
        if not np.all(np.isfinite(coefficients)):
            raise RigError(f"{where}: the flat field's coefficients are not finite", fix)
        return cls(
            coefficients,
            aspect,
            (centre[0], centre[1]),
            str(data.get("method", "")),
            dict(data.get("details") or {}),
        )


def _radius2(width: int, height: int, centre: tuple[float, float]) -> np.ndarray:
    """r² at every pixel centre (height, width), r = 1 at half the diagonal."""
    x = (np.arange(width) + 0.5) - centre[0] * width
    y = (np.arange(height) + 0.5) - centre[1] * height
    half_diagonal2 = (width**2 + height**2) / 4.0
    return (y[:, None] ** 2 + x[None, :] ** 2) / half_diagonal2


def card_shading(
    width: int,
    height: int,
    focal_px: float,
    distance_m: float,
    light_offset_m: Sequence[float] = (0.0, 0.0, 0.0),
    principal_px: tuple[float, float] | None = None,
) -> np.ndarray:
    """Irradiance ``(p − x)·n / |p − x|³`` a point light at ``light_offset_m`` (camera frame)
    gives a card facing the camera ``distance_m`` along its axis, at every pixel (the forward
    model's shading, docs/architecture.md#forward-model); relative to its value on the axis."""
    cx, cy = principal_px if principal_px is not None else (width / 2.0, height / 2.0)
    x = ((np.arange(width) + 0.5) - cx) / focal_px * distance_m
    y = ((np.arange(height) + 0.5) - cy) / focal_px * distance_m
    light = np.asarray(light_offset_m, dtype=float)
    dx = light[0] - x[None, :]
    dy = light[1] - y[:, None]
    dz = light[2] - distance_m
    shading = -dz / (dx**2 + dy**2 + dz**2) ** 1.5  # the card's normal faces the camera (−z)
    on_axis = -dz / (light[0] ** 2 + light[1] ** 2 + dz**2) ** 1.5
    if not np.all(shading > 0):
        raise RigError(
            f"the light at {tuple(light)} m does not light a card {distance_m:g} m away",
            "place the card in front of the camera and the light, facing them",
        )
    return shading / on_axis


def fit_flat_field(
    images: Sequence[np.ndarray],
    valid: Sequence[np.ndarray] | None = None,
    shading: np.ndarray | None = None,
    method: str = "white card",
    details: Mapping[str, Any] | None = None,
) -> FlatField:
    """Fit the flat field to linear images (H, W, 3) of a uniform white card (dark already
    subtracted), averaged; ``valid`` masks (H, W) exclude saturated pixels; ``shading`` (H, W)
    is the light's own fall-off on the card (:func:`card_shading`), divided out first."""
    if not images:
        raise RigError("no white card frames to fit a flat field to", "give at least one frame")
    height, width = images[0].shape[:2]
    total = np.zeros((height, width, 3))
    count = np.zeros((height, width))
    for i, image in enumerate(images):
        if image.shape != (height, width, 3):
            raise RigError(
                f"white card frame {i + 1} is {image.shape[1]}x{image.shape[0]}, the first is "
                f"{width}x{height}",
                "take every white card frame with the same camera and image size",
            )
        ok = np.ones((height, width), bool) if valid is None else np.asarray(valid[i], bool)
        total += np.where(ok[..., None], image, 0.0)
        count += ok
    mean = total / np.maximum(count, 1)[..., None]
    if shading is not None:
        mean = mean / shading[..., None]
    usable = count == len(images)
    blocks, r2, keep = _blocks(mean, usable, width, height)
    if keep.sum() < 4 * (ORDER + 1):
        raise RigError(
            "the white card frames have too few unsaturated pixels to fit a flat field",
            "shorten the exposure so the card is not clipped, and fill the frame with it",
        )
    coefficients = np.zeros((3, ORDER))
    rms = np.zeros(3)
    for c in range(3):
        k, rms[c] = _fit_channel(blocks[..., c][keep], r2[keep])
        coefficients[c] = k
    info = {
        "frames": len(images),
        "image_size": [width, height],
        "fit_rms": [round(float(v), 5) for v in rms],
        **dict(details or {}),
    }
    return FlatField(coefficients, width / height, method=method, details=info)


def _blocks(
    image: np.ndarray, usable: np.ndarray, width: int, height: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block means of ``image`` (only blocks wholly usable count), their r², and which count."""
    side = BLOCK_PX if min(width, height) >= 16 * BLOCK_PX else 1
    h, w = height // side * side, width // side * side
    cut = image[:h, :w].reshape(h // side, side, w // side, side, 3).mean(axis=(1, 3))
    ok = usable[:h, :w].reshape(h // side, side, w // side, side).all(axis=(1, 3))
    r2 = _radius2(width, height, (0.5, 0.5))[:h, :w]
    r2 = r2.reshape(h // side, side, w // side, side).mean(axis=(1, 3))
    return cut, r2, ok & np.all(cut > 0, axis=-1)


def _fit_channel(values: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, float]:
    """Least squares of ``values ≈ c0 (1 + Σ k r^2j)``, then again without outlying blocks;
    returns (k, relative RMS of the fit)."""
    design = np.stack([r2**j for j in range(ORDER + 1)], axis=1)
    keep = np.ones(len(values), bool)
    for _ in range(2):
        coef = np.linalg.lstsq(design[keep], values[keep], rcond=None)[0]
        residual = values - design @ coef
        sigma = float(np.std(residual[keep])) or 1.0
        keep = np.abs(residual) <= CLIP_SIGMA * sigma
    if not coef[0] > 0:
        raise RigError(
            "the white card frames are dark at the centre",
            "light the card and fill the frame with it",
        )
    rms = float(np.sqrt(np.mean((residual[keep] / coef[0]) ** 2)))
    return coef[1:] / coef[0], rms
