"""Compiled reads of the frames at projected points: bilinear samples (float16 frames
decoded by table) and the camera projection with its Jacobian."""

from __future__ import annotations

import numpy as np
from numba import njit, prange, types
from numba.extending import overload

# float16 as float64, by bit pattern: numba has no float16 type on the CPU, so float16 frames
# reach the kernels as their uint16 bits and are decoded by this table (exact, 0.5 MB).
HALF_TABLE = np.arange(2**16, dtype=np.uint16).view(np.float16).astype(np.float64)
_NO_TABLE = np.empty(0)


def texel(texels: np.ndarray, table: np.ndarray, f: int, r: int, c: int, ch: int) -> float:
    """One image value as float64: ``texels`` are floats, or float16 bits decoded by ``table``."""
    raise NotImplementedError("compiled only (numba overload below)")


@overload(texel, inline="always")
def _texel(texels, table, f, r, c, ch):
    if isinstance(texels.dtype, types.Integer):
        return lambda texels, table, f, r, c, ch: table[texels[f, r, c, ch]]
    return lambda texels, table, f, r, c, ch: float(texels[f, r, c, ch])


def sample_bilinear(
    images: np.ndarray,
    frame: np.ndarray,
    obs_pair: np.ndarray,
    index: np.ndarray,
    frac: np.ndarray,
    gradient: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear values (M, C) of ``images`` (F, H, W, C) and with ``gradient`` their
    ``∂value/∂(u, v)`` (M, C, 2) (else an empty array). Observation m reads frame
    ``frame[m]`` at the taps of its pair ``obs_pair[m]``: the flat top-left tap ``index`` (P,)
    and the fractions ``frac`` (P, 2) along columns and rows (``sampling.bilinear_taps``).
    float16 images are read through :data:`HALF_TABLE`."""
    half = images.dtype == np.float16
    texels, table = (images.view(np.uint16), HALF_TABLE) if half else (images, _NO_TABLE)
    return _sample_bilinear(texels, table, frame, obs_pair, index, frac, gradient)


@njit(parallel=True, cache=True, fastmath=True)
def _sample_bilinear(
    texels: np.ndarray,
    table: np.ndarray,
    frame: np.ndarray,
    obs_pair: np.ndarray,
    index: np.ndarray,
    frac: np.ndarray,
    gradient: bool,
) -> tuple[np.ndarray, np.ndarray]:
    m_count = obs_pair.size
    width, nc = texels.shape[2], texels.shape[3]
    value = np.empty((m_count, nc))
    grad = np.empty((m_count if gradient else 0, nc, 2))
    for m in prange(m_count):
        p = obs_pair[m]
        r0, c0 = divmod(index[p], width)
        fc, fr = frac[p, 0], frac[p, 1]
        f = frame[m]
        for c in range(nc):
            i00 = texel(texels, table, f, r0, c0, c)
            i01 = texel(texels, table, f, r0, c0 + 1, c)
            i10 = texel(texels, table, f, r0 + 1, c0, c)
            i11 = texel(texels, table, f, r0 + 1, c0 + 1, c)
            d0 = i01 - i00
            d1 = i11 - i10
            top = i00 + fc * d0
            dv = i10 + fc * d1 - top
            value[m, c] = top + fr * dv
            if gradient:
                grad[m, c, 0] = d0 + fr * (d1 - d0)
                grad[m, c, 1] = dv
    return value, grad


@njit(parallel=True, cache=True)
def project_points(
    X: np.ndarray,
    vertex: np.ndarray,
    view: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    camera: np.ndarray,
    distortion: np.ndarray,
    gradient: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (P, 2) of the points ``X[vertex]`` in views ``view`` (P,), and with
    ``gradient`` ``∂uv/∂x`` (P, 2, 3) (else empty), in one pass: the optimiser projects every
    (vertex, view) pair at each evaluation, where NumPy's passes over (P, 2, 3) arrays cost a
    large share of the solve. Per view: world->camera ``R`` (V, 3, 3), ``t`` (V, 3); ``camera``
    (V, 4) = fx, fy, cx, cy; ``distortion`` (V, 4) = OpenCV k1, k2, p1, p2
    (:meth:`Intrinsics.distortion`). A compiled copy of :meth:`Intrinsics.project_camera`
    (points on or behind the camera plane project to NaN); ``test_sampling.py`` holds the two
    equal."""
    n = vertex.size
    uv = np.empty((n, 2))
    duv = np.empty((n if gradient else 0, 2, 3))
    for p in prange(n):
        i, c = vertex[p], view[p]
        w0, w1, w2 = X[i, 0], X[i, 1], X[i, 2]
        xc0 = R[c, 0, 0] * w0 + R[c, 0, 1] * w1 + R[c, 0, 2] * w2 + t[c, 0]
        xc1 = R[c, 1, 0] * w0 + R[c, 1, 1] * w1 + R[c, 1, 2] * w2 + t[c, 1]
        z = R[c, 2, 0] * w0 + R[c, 2, 1] * w1 + R[c, 2, 2] * w2 + t[c, 2]
        k1, k2, p1, p2 = distortion[c, 0], distortion[c, 1], distortion[c, 2], distortion[c, 3]
        fx, fy = camera[c, 0], camera[c, 1]
        # normalised coordinates and the radial factor, shared by the pixel and its Jacobian
        inv_z = 1.0 / (z if abs(z) > 1e-12 else 1e-12)
        x, y = xc0 * inv_z, xc1 * inv_z
        r2 = x * x + y * y
        radial = 1.0 + k1 * r2 + k2 * r2 * r2
        if z > 0.0:
            uv[p, 0] = fx * (x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)) + camera[c, 2]
            uv[p, 1] = fy * (y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y) + camera[c, 3]
        else:
            uv[p, 0] = uv[p, 1] = np.nan
        if not gradient:
            continue
        # ∂(x, y)/∂x_c = (1/z) [[1, 0, −x], [0, 1, −y]]; the distortion's 2×2 on the left
        slope = 2.0 * (k1 + 2.0 * k2 * r2)
        cross = slope * x * y + 2.0 * p1 * x + 2.0 * p2 * y
        a = radial + slope * x * x + 2.0 * p1 * y + 6.0 * p2 * x
        d = radial + slope * y * y + 6.0 * p1 * y + 2.0 * p2 * x
        a0, a1, a2 = fx * a * inv_z, fx * cross * inv_z, -fx * (a * x + cross * y) * inv_z
        b0, b1, b2 = fy * cross * inv_z, fy * d * inv_z, -fy * (cross * x + d * y) * inv_z
        for col in range(3):
            duv[p, 0, col] = a0 * R[c, 0, col] + a1 * R[c, 1, col] + a2 * R[c, 2, col]
            duv[p, 1, col] = b0 * R[c, 0, col] + b1 * R[c, 1, col] + b2 * R[c, 2, col]
    return uv, duv
