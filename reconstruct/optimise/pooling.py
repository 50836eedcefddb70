"""Colour for the vertices whose shape the solve left folded, from neighbours that agree.

Where the joint stages leave a vertex's normal tilted against those around it, its views read
the object at the wrong place and angle, and its own reflectance is off in hue as well as in
lightness; a neighbour on settled surface, in the same paint, read it better. A vertex counts
as folded where its normal is more than ``max_fold_deg`` from the mean normal of its 2-ring:
on a smooth surface, curved or not, that mean is the vertex's own normal, so only a fold or a
dent narrower than the ring stands out (a crease in the object itself does too, and keeps its
colour unless its neighbours agree). A folded vertex takes the reflectance of the medoid of
its ``neighbours`` nearest settled vertices on its side of the surface when they agree (a share
``agree_share`` of them within ``agree_rmse`` of that medoid: one paint, not an edge), and
keeps its own otherwise. The medoid is one of them, so the spectrum is a measured one,
inside the physical bounds and the basis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from core.config import bounded
from reconstruct.optimise.mesh import adjacency, vertex_normals

# targets per block of the pairwise candidate distances (block × k² × N_λ floats)
BLOCK = 1024


@dataclass
class PoolingSettings:
    """The ``optimise.pooling`` section of a reconstruct config."""

    # 0 turns the pooling off
    max_fold_deg: float = bounded(5.0, min=0.0, max=180.0)
    neighbours: int = bounded(16, min=2, max=1000)
    agree_rmse: float = bounded(0.05, above=0.0, max=1.0)
    agree_share: float = bounded(0.8, above=0.0, max=1.0)


def fold_angles(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per vertex: the angle (degrees) between its normal and the mean normal of its 2-ring,
    and that mean normal (unit, (N, 3)).

    >>> import trimesh
    >>> s = trimesh.creation.icosphere(3)
    >>> angle, _ = fold_angles(s.vertices, s.faces)
    >>> bool(angle.max() < 1.0)
    True
    """
    n, _ = vertex_normals(vertices, faces)
    a = adjacency(faces, len(vertices))
    ring2 = a @ a + a
    ring2.data[:] = 1.0
    mean = ring2 @ n
    mean /= np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-300)
    cos = np.clip(np.einsum("ij,ij->i", n, mean), -1.0, 1.0)
    return np.degrees(np.arccos(cos)), mean


def pooled_sources(
    vertices: np.ndarray,
    faces: np.ndarray,
    reflectance: np.ndarray,
    observed: np.ndarray,
    settings: PoolingSettings,
) -> np.ndarray:
    """Per vertex (N,): the vertex whose reflectance it takes, itself where it keeps its own.

    Only observed vertices are folded or serve as sources; ``reflectance`` (N, N_λ)."""
    source = np.arange(len(vertices))
    if settings.max_fold_deg <= 0:
        return source
    angle, mean_normal = fold_angles(vertices, faces)
    folded = observed & (angle > settings.max_fold_deg)
    settled = np.flatnonzero(observed & ~folded)
    targets = np.flatnonzero(folded)
    k = min(settings.neighbours, len(settled))
    if k < 2 or targets.size == 0:
        return source
    _, near = cKDTree(vertices[settled]).query(vertices[targets], k=min(4 * k, len(settled)))
    near = settled[near]  # (T, 4k) vertex indices, nearest first
    # a thin part's other side is near in space but not on this surface: the k nearest on
    # the vertex's own side
    same_side = np.einsum("tj,tkj->tk", mean_normal[targets], mean_normal[near]) > 0.0
    order = np.argsort(~same_side, axis=1, kind="stable")[:, :k]
    near = np.take_along_axis(near, order, axis=1)
    same_side = np.take_along_axis(same_side, order, axis=1)
    for lo in range(0, targets.size, BLOCK):
        t, cand, ok = targets[lo : lo + BLOCK], near[lo : lo + BLOCK], same_side[lo : lo + BLOCK]
        r = reflectance[cand]  # (b, k, N_λ)
        dist = np.sqrt(np.mean((r[:, :, None, :] - r[:, None, :, :]) ** 2, axis=-1))
        dist = np.where(ok[:, None, :], dist, np.nan)  # (b, k, k): to the same-side ones only
        centrality = np.where(ok, np.nansum(dist, axis=2), np.inf)
        medoid = np.argmin(centrality, axis=1)
        spread = dist[np.arange(len(t)), medoid]  # (b, k), NaN off the surface's side
        count = ok.sum(axis=1)
        agree = np.sum(spread <= settings.agree_rmse, axis=1)
        take = (count >= k / 2) & (agree >= settings.agree_share * count)
        source[t[take]] = cand[np.arange(len(t)), medoid][take]
    return source
