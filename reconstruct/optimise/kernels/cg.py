"""Compiled vector updates of the conjugate-gradient inner solve and the projection onto a
stage's parameters."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True, fastmath=True)
def cg_step(x: np.ndarray, r: np.ndarray, d: np.ndarray, q: np.ndarray, step: float) -> float:
    """CG's update ``x += step d``, ``r −= step q`` in place, in one pass; returns |r|²
    (NumPy would take four passes and two temporaries of θ's size)."""
    acc = 0.0
    for i in prange(x.shape[0]):
        x[i] += step * d[i]
        ri = r[i] - step * q[i]
        r[i] = ri
        acc += ri * ri
    return acc


@njit(parallel=True, cache=True, fastmath=True)
def cg_direction(d: np.ndarray, z: np.ndarray, beta: float) -> None:
    """CG's next search direction ``d = z + β d``, in place."""
    for i in prange(d.shape[0]):
        d[i] = z[i] + beta * d[i]


@njit(parallel=True, cache=True, fastmath=True)
def project_to_stage(
    v: np.ndarray, damping: np.ndarray, step: np.ndarray, mask: np.ndarray, directions: np.ndarray
) -> None:
    """In place: ``v = P (v + damping ⊙ step)`` with P the stage's projection — the mask, then
    each vertex's position (θ's first 3N entries) onto its direction ``d dᵀ`` (``directions``
    (N, 3); empty: free motion). Empty ``damping``: no damping term."""
    damped = damping.shape[0] > 0
    for i in prange(v.shape[0]):
        vi = v[i] + damping[i] * step[i] if damped else v[i]
        v[i] = vi if mask[i] else 0.0
    for i in prange(directions.shape[0]):
        s = v[3 * i] * directions[i, 0] + v[3 * i + 1] * directions[i, 1]
        s += v[3 * i + 2] * directions[i, 2]
        for a in range(3):
            v[3 * i + a] = directions[i, a] * s
