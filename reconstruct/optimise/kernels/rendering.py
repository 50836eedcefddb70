"""Compiled per-observation passes of the rendering term: the residuals and the shading's
derivatives."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True, fastmath=True)
def rendered_error(
    colours: np.ndarray,
    pair_shading: np.ndarray,
    obs_pair: np.ndarray,
    vertex: np.ndarray,
    illumination: np.ndarray,
    observed: np.ndarray,
) -> np.ndarray:
    """Per observation the error s c − y_obs (M, 3), with s its pair's shading and c
    ``colours[ill, vertex]``, in one pass (no per-observation s or c is kept in memory)."""
    m_count = obs_pair.size
    error = np.empty((m_count, 3))
    for m in prange(m_count):
        sm = pair_shading[obs_pair[m]]
        for ch in range(3):
            error[m, ch] = sm * colours[illumination[m], vertex[m], ch] - observed[m, ch]
    return error


@njit(parallel=True, cache=True, fastmath=True)
def shading_gradients(
    x: np.ndarray,
    normals: np.ndarray,
    lights: np.ndarray,
    pair_vertex: np.ndarray,
    pair_view: np.ndarray,
    pair_s: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The derivatives of the shading ``s = (p − x)·n / |p − x|³`` (``forward.shading``) per
    (vertex, view) pair: ``g = ∂s/∂p = n/|d|³ − 3 (d·n) d/|d|⁵`` (= −∂s/∂x with n fixed) and
    ``h = ∂s/∂n = d/|d|³`` with d = p − x, zero where the pair is unlit (``pair_s`` ≤ 0).
    One pass instead of a dozen NumPy temporaries of (pairs × 3)."""
    m = pair_vertex.shape[0]
    g = np.empty((m, 3))
    h = np.empty((m, 3))
    for t in prange(m):
        if not pair_s[t] > 0.0:
            for a in range(3):
                g[t, a] = 0.0
                h[t, a] = 0.0
            continue
        i, c = pair_vertex[t], pair_view[t]
        d0, d1, d2 = lights[c, 0] - x[i, 0], lights[c, 1] - x[i, 1], lights[c, 2] - x[i, 2]
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        dist2 = d0 * d0 + d1 * d1 + d2 * d2
        inv3 = 1.0 / (dist2 * np.sqrt(dist2))
        k = 3.0 * (d0 * n0 + d1 * n1 + d2 * n2) * inv3 / dist2
        g[t, 0], g[t, 1], g[t, 2] = n0 * inv3 - k * d0, n1 * inv3 - k * d1, n2 * inv3 - k * d2
        h[t, 0], h[t, 1], h[t, 2] = d0 * inv3, d1 * inv3, d2 * inv3
    return g, h
