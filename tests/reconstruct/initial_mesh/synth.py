"""Synthetic Gray-code captures with a known projector coordinate per camera pixel."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter, zoom

from drivers.projectors.patterns import gray_code_sequence


def smooth_field(rng: np.random.Generator, shape: tuple[int, int], lo: float, hi: float,
                 cells: int = 4) -> np.ndarray:
    """A random smooth field in [lo, hi] (bicubic upsampling of a coarse random grid)."""
    coarse = rng.random((cells, cells))
    f = zoom(coarse, (shape[0] / cells, shape[1] / cells), order=3, mode="nearest")
    f = (f - f.min()) / (np.ptp(f) or 1.0)
    return lo + (hi - lo) * f[: shape[0], : shape[1]]


def coordinate_map(rng: np.random.Generator, height: int, width: int, ss: int,
                   proj: tuple[int, int], curved: bool) -> np.ndarray:
    """Projector (x, y) at each sub-pixel centre (height*ss, width*ss, 2): a tilted plane seen
    by both devices (a homography), optionally bent by a smooth random surface."""
    v, u = np.mgrid[0:height * ss, 0:width * ss]
    u = (u + 0.5) / ss / width
    v = (v + 0.5) / ss / height
    w = 1.0 + 0.25 * u - 0.1 * v
    x = proj[0] * (0.05 + 0.85 * u + 0.05 * v) / w
    y = proj[1] * (0.1 + 0.03 * u + 0.8 * v) / w
    if curved:
        bend = smooth_field(rng, x.shape, -1.0, 1.0, cells=5)
        x = x + 0.03 * proj[0] * bend
        y = y + 0.02 * proj[1] * bend
    return np.stack([x, y], axis=-1)


def capture_stack(seed: int = 0, height: int = 96, width: int = 128,
                  proj: tuple[int, int] = (64, 48), blur: float = 0.7, noise: float = 0.01,
                  ambient: float = 0.15, curved: bool = True, ss: int = 4,
                  colour: bool = True) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """Pattern id -> camera image, true (col, row) per pixel centre (H, W, 2), and the mask of
    pixels the projector truly lights (not shadowed, inside its frame)."""
    rng = np.random.default_rng(seed)
    xy = coordinate_map(rng, height, width, ss, proj, curved)
    centre = xy[ss // 2 :: ss, ss // 2 :: ss]
    truth = np.floor(centre).astype(int)
    col = np.clip(np.floor(xy[..., 0]).astype(int), 0, proj[0] - 1)
    row = np.clip(np.floor(xy[..., 1]).astype(int), 0, proj[1] - 1)
    inside_ss = (xy[..., 0] >= 0) & (xy[..., 0] < proj[0]) & (xy[..., 1] >= 0) & (
        xy[..., 1] < proj[1])
    vv, uu = np.mgrid[0:height, 0:width]
    shadow = (uu - 0.3 * width) ** 2 + (vv - 0.6 * height) ** 2 < (0.12 * height) ** 2
    albedo = smooth_field(rng, (height, width), 0.25, 1.0)
    tint = rng.uniform(0.4, 1.0, 3) if colour else np.ones(3)
    amb = ambient * smooth_field(rng, (height, width), 0.5, 1.0)
    images = {}
    for label, pattern in gray_code_sequence(*proj):
        lit = (pattern[row, col] / 255.0) * inside_ss
        cam = lit.reshape(height, ss, width, ss).mean(axis=(1, 3))
        cam = gaussian_filter(cam, blur) if blur else cam
        cam = cam * ~shadow
        grey = albedo * (0.8 * cam + amb)
        img = grey[..., None] * tint
        img = img + rng.normal(0.0, noise, img.shape)
        images[label] = np.clip(img, 0.0, 1.0).astype(np.float32)
    inside = (truth[..., 0] >= 0) & (truth[..., 0] < proj[0]) & (truth[..., 1] >= 0) & (
        truth[..., 1] < proj[1])
    return images, truth, inside & ~shadow
