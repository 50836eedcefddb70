"""Observed colours at projected vertices: bilinear samples, their image gradients and the
Jacobian of the projection — the disparity cue of the rendering term (paper Sec. 3.3.1).

Pixel convention (docs/architecture.md, Cameras and poses): the centre of array element ``[row,
col]`` is at pixel coordinates ``(col + 0.5, row + 0.5)``. The bilinear interpolant is piecewise
linear, so its gradient (used for ``∂y_obs/∂x``) is exact inside each pixel cell.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.ndimage import gaussian_filter

from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.optimise.kernels.sampling import sample_bilinear
from reconstruct.optimise.problem import Frames


def bilinear(
    images: np.ndarray, frame: np.ndarray, uv: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Sample ``images`` (F, H, W, C) of frame ``frame`` (M,) at pixel coords ``uv`` (M, 2).

    Returns values (M, C) and the gradient ``∂value/∂(u, v)`` (M, C, 2). Coordinates are
    clamped to the image so samples stay defined while a vertex moves near the border.
    """
    value, grad = sample_taps(images, frame, bilinear_taps(images.shape[1:3], uv), gradient=True)
    assert grad is not None
    return value, grad


def sample_pairs(
    images: np.ndarray, frame: np.ndarray, obs_pair: np.ndarray, uv: np.ndarray, gradient: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Compiled :func:`bilinear`: observation m reads frame ``frame[m]`` at its pair's pixel
    coords ``uv[obs_pair[m]]`` (``uv`` (P, 2), one projection's taps for every frame of that
    view). Values (M, C) and with ``gradient`` ``∂value/∂(u, v)`` (M, C, 2), else empty."""
    index, fc, fr = bilinear_taps(images.shape[1:3], uv)
    frac = np.concatenate([fc, fr], axis=1)
    return sample_bilinear(images, frame, obs_pair, index, frac, gradient)


Taps = tuple[np.ndarray, np.ndarray, np.ndarray]


def bilinear_taps(size: tuple[int, int], uv: np.ndarray) -> Taps:
    """Where the bilinear samples of pixel coords ``uv`` (M, 2) read an (H, W) image: the flat
    index of the top-left tap and the fractional offsets (M, 1) along columns and rows. One
    projection's taps serve every frame taken from that view."""
    h, w = size
    # A trial step can take a vertex behind a camera (projection NaN): clamp it like any
    # point off the image, so the step is evaluated (and rejected) instead of failing.
    uv = np.nan_to_num(uv, nan=0.0)
    col = np.clip(uv[:, 0] - 0.5, 0.0, w - 1.000001)
    row = np.clip(uv[:, 1] - 0.5, 0.0, h - 1.000001)
    c0 = np.minimum(np.floor(col).astype(np.int64), w - 2)
    r0 = np.minimum(np.floor(row).astype(np.int64), h - 2)
    return r0 * w + c0, (col - c0)[:, None], (row - r0)[:, None]


def sample_taps(
    images: np.ndarray, frame: np.ndarray, taps: Taps, gradient: bool
) -> tuple[np.ndarray, np.ndarray | None]:
    """Bilinear values (M, C) of ``images`` (F, H, W, C) at ``taps`` in frames ``frame`` (M,),
    and with ``gradient`` their ``∂value/∂(u, v)`` (M, C, 2)."""
    _, h, w, nc = images.shape
    flat = images.reshape(-1, nc)
    index, fc, fr = taps
    at = frame.astype(np.int64) * (h * w) + index  # frames × pixels passes 2³¹ at 24 MP
    # One take of the four interleaved taps (np.take is ~3× faster than fancy indexing here).
    quad = np.take(flat, (at[:, None] + np.array([0, 1, w, w + 1])).ravel(), axis=0)
    quad = quad.reshape(len(at), 4, nc).astype(float)
    i00, i01, i10, i11 = quad[:, 0], quad[:, 1], quad[:, 2], quad[:, 3]
    d0 = i01 - i00
    d1 = i11 - i10
    top = i00 + fc * d0
    bottom = i10 + fc * d1
    dv = bottom - top
    value = top + fr * dv
    if not gradient:
        return value, None
    du = d0 + fr * (d1 - d0)
    return value, np.stack([du, dv], axis=-1)


def blur_frames(frames: Frames, sigma: np.ndarray) -> Frames:
    """``frames`` with each image blurred by a Gaussian of ``sigma[view]`` pixels — a coarse
    level, whose bilinear gradient reaches about σ. Normalised by the blurred validity mask,
    so saturated pixels do not bleed in; a pixel stays valid where valid ones carry more than
    half of its weight."""
    assert frames.images is not None and frames.valid is not None
    images = np.empty_like(frames.images)
    valid = np.empty_like(frames.valid)
    # filtered in float32 at least (ndimage has no float16), stored as the frames are
    work = np.promote_types(images.dtype, np.float32)
    for f in range(frames.count):
        s = float(sigma[frames.view[f]])
        mask = frames.valid[f].astype(work)
        weight = gaussian_filter(mask, s, mode="nearest")
        kept = np.where(frames.valid[f][..., None], frames.images[f], 0).astype(work)
        blurred = gaussian_filter(kept, (s, s, 0), mode="nearest")
        valid[f] = weight > 0.5
        images[f] = blurred / np.maximum(weight, 1e-6)[..., None]
    return replace(frames, images=images, valid=valid)


def taps_valid(
    valid: np.ndarray, frame: np.ndarray, uv: np.ndarray, margin: float = 1.0
) -> np.ndarray:
    """True where ``uv`` lies ``margin`` px inside the image and all four bilinear taps are valid
    (not saturated) in ``valid`` (F, H, W) bool."""
    h, w = valid.shape[1:3]
    with np.errstate(invalid="ignore"):
        inside = (
            (uv[:, 0] >= margin)
            & (uv[:, 0] <= w - margin)
            & (uv[:, 1] >= margin)
            & (uv[:, 1] <= h - margin)
        )
    out = np.zeros(len(uv), dtype=bool)
    idx = np.flatnonzero(inside)
    col = uv[idx, 0] - 0.5
    row = uv[idx, 1] - 0.5
    c0 = np.clip(np.floor(col).astype(np.int64), 0, w - 2)
    r0 = np.clip(np.floor(row).astype(np.int64), 0, h - 2)
    f = frame[idx]
    out[idx] = (
        valid[f, r0, c0] & valid[f, r0, c0 + 1] & valid[f, r0 + 1, c0] & valid[f, r0 + 1, c0 + 1]
    )
    return out


ViewCameras = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def view_cameras(intrinsics: list[Intrinsics], poses: list[Pose]) -> ViewCameras:
    """Per view R (V, 3, 3), t (V, 3), (fx, fy, cx, cy) (V, 4) and OpenCV (k1, k2, p1, p2)
    (V, 4): the arrays :func:`~reconstruct.optimise.kernels.sampling.project_points` reads."""
    R = np.stack([np.asarray(pose.R, dtype=float) for pose in poses])
    t = np.stack([np.asarray(pose.t, dtype=float) for pose in poses])
    camera = np.array([[i.K[0, 0], i.K[1, 1], i.K[0, 2], i.K[1, 2]] for i in intrinsics])
    distortion = np.stack([i.distortion() for i in intrinsics]).astype(float)
    return R, t, camera, distortion
