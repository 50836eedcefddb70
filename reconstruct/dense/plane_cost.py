"""The PatchMatch inner loop, compiled: 1 - NCC of plane hypotheses against source views.

Scoring one (pixel, plane) pair touches every window sample of every illumination in every
source view, millions of times per view; NumPy would build (pixels x samples x sources)
temporaries for each proposal, so this loop is compiled with numba and runs over pixels in
parallel. Cameras are pinhole here (images are undistorted before matching).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

INVALID_COST = 2.0  # 1 - NCC ranges over [0, 2]; a window that leaves a source view gets this


@njit(cache=True, fastmath=True)
def _source_cost(
    u: float, v: float, H: np.ndarray, ref: np.ndarray, du: np.ndarray, dv: np.ndarray,
    image: np.ndarray, min_texture: float,
) -> float:
    """1 - NCC of one window warped into one source image by the plane's homography ``H``
    (reference pixel -> source pixel, pixel-corner coordinates)."""
    n_samples, n_illum = ref.shape
    height, width = image.shape[0], image.shape[1]
    sums = np.zeros(n_illum)
    squares = np.zeros(n_illum)
    cross = 0.0
    for j in range(n_samples):
        x, y = u + du[j], v + dv[j]
        hz = H[2, 0] * x + H[2, 1] * y + H[2, 2]
        if hz <= 0.0:
            return INVALID_COST
        us = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / hz - 0.5
        vs = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / hz - 0.5
        if not (0.0 <= us < width - 1.0 and 0.0 <= vs < height - 1.0):
            return INVALID_COST
        c0, r0 = int(us), int(vs)
        fu, fv = us - c0, vs - r0
        for i in range(n_illum):
            value = ((1 - fv) * ((1 - fu) * image[r0, c0, i] + fu * image[r0, c0 + 1, i])
                     + fv * ((1 - fu) * image[r0 + 1, c0, i] + fu * image[r0 + 1, c0 + 1, i]))
            sums[i] += value
            squares[i] += value * value
            cross += ref[j, i] * value  # ref is centred per illumination: no mean needed
    variance = 0.0
    level = 0.0
    for i in range(n_illum):
        variance += squares[i] - sums[i] * sums[i] / n_samples
        level += abs(sums[i]) / n_samples
    level *= np.sqrt(n_samples * n_illum) / n_illum
    if variance <= (min_texture * level) ** 2 or variance <= 0.0:
        return INVALID_COST
    return 1.0 - cross / np.sqrt(variance)


@njit(parallel=True, cache=True, fastmath=True)
def plane_costs(
    u: np.ndarray, v: np.ndarray, rays: np.ndarray, distance: np.ndarray, normal: np.ndarray,
    ref: np.ndarray, du: np.ndarray, dv: np.ndarray, inv: np.ndarray,
    images: np.ndarray, A: np.ndarray, b: np.ndarray, top_k: int, min_texture: float,
) -> np.ndarray:
    """Cost of the plane through each pixel's point at ``distance`` along its unit ``ray``
    with camera-frame ``normal``: the mean of the ``top_k`` best sources' 1 - NCC.

    ``u, v`` pixel coordinates (N,); ``ref`` (N, J, I) reference windows, centred per
    illumination and of unit norm; ``du, dv`` (J,) window offsets; ``inv`` (fx, fy, cx, cy)
    of the reference; ``images`` (S, H, W, I); ``A = K_s R``, ``b = K_s t`` (S, 3, 3), (S, 3)
    the reference-camera-to-source-pixel maps.
    """
    n = len(u)
    n_sources = images.shape[0]
    k = min(top_k, n_sources)
    out = np.empty(n)
    K_inv = np.array([[1.0 / inv[0], 0.0, -inv[2] / inv[0]],
                      [0.0, 1.0 / inv[1], -inv[3] / inv[1]],
                      [0.0, 0.0, 1.0]])
    for p in prange(n):
        nx, ny, nz = normal[p, 0], normal[p, 1], normal[p, 2]
        rho = distance[p] * (nx * rays[p, 0] + ny * rays[p, 1] + nz * rays[p, 2])
        costs = np.empty(n_sources)
        if rho >= 0.0:  # the plane faces away from the camera
            out[p] = INVALID_COST
            continue
        # points X on the plane n.X = rho map to A X + b = (A + b n^T / rho) X: a homography
        # H = (A + b n^T / rho) K^-1 from reference pixels to source pixels
        H = np.empty((3, 3))
        for s in range(n_sources):
            for r in range(3):
                m0 = A[s, r, 0] + b[s, r] * nx / rho
                m1 = A[s, r, 1] + b[s, r] * ny / rho
                m2 = A[s, r, 2] + b[s, r] * nz / rho
                H[r, 0] = m0 * K_inv[0, 0]
                H[r, 1] = m1 * K_inv[1, 1]
                H[r, 2] = m0 * K_inv[0, 2] + m1 * K_inv[1, 2] + m2
            costs[s] = _source_cost(u[p], v[p], H, ref[p], du, dv, images[s], min_texture)
        costs.sort()
        out[p] = costs[:k].mean()
    return out
