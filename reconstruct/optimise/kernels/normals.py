"""Compiled vertex normals and the blocks of their Jacobian ``∂n/∂X``."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True)
def face_normal_sums(x: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``ñ_i`` (N, 3): each face's (twice-area) normal added to its three corners, face by
    face (the order NumPy's per-component ``bincount`` summed in; one pass instead of three)."""
    out = np.zeros((x.shape[0], 3))
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        e0, e1, e2 = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
        g0, g1, g2 = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
        n0, n1, n2 = e1 * g2 - e2 * g1, e2 * g0 - e0 * g2, e0 * g1 - e1 * g0
        for v in (a, b, c):
            out[v, 0] += n0
            out[v, 1] += n1
            out[v, 2] += n2
    return out


@njit(parallel=True, cache=True)
def normal_jacobian_blocks(
    x: np.ndarray,
    faces: np.ndarray,
    inverse: np.ndarray,
    n_blocks: int,
    block_row: np.ndarray,
    normals: np.ndarray,
    inverse_length: np.ndarray,
) -> np.ndarray:
    """The blocks of ``∂n/∂X`` (see ``mesh.NormalJacobian``): per face the edge vector
    ``w`` of each (corner i, corner j) pair summed into block ``inverse[9f + 3i + j]``
    (serial: faces share blocks), then ``([w]_× − n (n × w)ᵀ) / |ñ|`` per block."""
    w = np.zeros((n_blocks, 3))
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        for j in range(3):  # ∂N/∂x_j = [x_p − x_q]_×: (c, b) for a, (a, c) for b, (b, a) for c
            p, q = (c, b) if j == 0 else ((a, c) if j == 1 else (b, a))
            for i in range(3):
                blk = inverse[9 * f + 3 * i + j]
                for d in range(3):
                    w[blk, d] += x[p, d] - x[q, d]
    out = np.empty((n_blocks, 3, 3))
    for t in prange(n_blocks):
        r = block_row[t]
        n0, n1, n2 = normals[r, 0], normals[r, 1], normals[r, 2]
        w0, w1, w2 = w[t, 0], w[t, 1], w[t, 2]
        c0, c1, c2 = n1 * w2 - n2 * w1, n2 * w0 - n0 * w2, n0 * w1 - n1 * w0  # n × w
        s = inverse_length[r]
        out[t, 0, 0] = (0.0 - n0 * c0) * s
        out[t, 0, 1] = (-w2 - n0 * c1) * s
        out[t, 0, 2] = (w1 - n0 * c2) * s
        out[t, 1, 0] = (w2 - n1 * c0) * s
        out[t, 1, 1] = (0.0 - n1 * c1) * s
        out[t, 1, 2] = (-w0 - n1 * c2) * s
        out[t, 2, 0] = (-w1 - n2 * c0) * s
        out[t, 2, 1] = (w0 - n2 * c1) * s
        out[t, 2, 2] = (0.0 - n2 * c2) * s
    return out
