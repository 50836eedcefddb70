"""Weights that depend on the current estimate and are frozen during one solve.

Photometric smoothness weights (paper eq. 15, after MVIR, Kim et al. 2016): neighbouring
vertices whose observed colours differ are allowed to differ in reflectance. For each vertex we
pool, per illumination, its observations into a chromaticity ``Σ y / Σ (R+G+B)`` (independent
of shading; dark, e.g. wrongly unmasked shadowed, observations weigh little) and a
shading-corrected intensity ``Σ s (R+G+B) / Σ s²`` (least-squares albedo intensity), then

    w_ij = exp(−‖Δchroma‖² / σ_c²) · exp(−(Δ log intensity)² / σ_I²)

averaged over the illuminations both vertices are observed under. Unobserved vertices take
their reflectance from their neighbours: weight 1 between two unobserved vertices, and a small
``fill_weight`` from an observed to an unobserved one, so the fill follows the observed surface
without pulling observed boundary vertices towards it.
Geometric scale l_i (eq. 16): the mean length of the edges at vertex i, so the geometric term is
scale free as in MVIR.

Tap weights (the final colour stage): an observation whose bilinear tap sits where the image
changes fast (a paint, shadow or silhouette edge) reads a mix of two surfaces, so it weighs less
in the reflectance.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def photometric_weights(
    edges: np.ndarray,
    vertex: np.ndarray,
    illumination: np.ndarray,
    observed: np.ndarray,
    shading: np.ndarray,
    n_vertices: int,
    n_illuminations: int,
    sigma_chroma: float,
    sigma_intensity: float,
    fill_weight: float = 1e-3,
) -> np.ndarray:
    """w_ij per edge from observations (vertex, illumination, observed RGB, shading)."""
    total = observed.sum(axis=1)
    ok = (total > 0) & (shading > 0)
    rgb = np.zeros((n_vertices, n_illuminations, 3))
    st = np.zeros((n_vertices, n_illuminations))
    ss = np.zeros((n_vertices, n_illuminations))
    v, k = vertex[ok], illumination[ok]
    np.add.at(rgb, (v, k), observed[ok])
    np.add.at(st, (v, k), shading[ok] * total[ok])
    np.add.at(ss, (v, k), shading[ok] ** 2)
    seen = (ss > 0) & (st > 0)
    chroma = np.zeros_like(rgb)
    logi = np.zeros_like(st)
    chroma[seen] = rgb[seen] / rgb[seen].sum(axis=1, keepdims=True)
    logi[seen] = np.log(st[seen] / ss[seen])
    i, j = edges[:, 0], edges[:, 1]
    both = seen[i] & seen[j]
    dc = np.sum((chroma[i] - chroma[j]) ** 2, axis=2) / sigma_chroma**2
    di = (logi[i] - logi[j]) ** 2 / sigma_intensity**2
    w = np.exp(-(dc + di)) * both
    n_both = both.sum(axis=1)
    any_i, any_j = seen[i].any(axis=1), seen[j].any(axis=1)
    fill = np.where(any_i | any_j, fill_weight, 1.0)
    return np.where(n_both > 0, w.sum(axis=1) / np.maximum(n_both, 1), fill)


def tap_weights(values: np.ndarray, gradient: np.ndarray, scale: float) -> np.ndarray:
    """Factor per observation ``1 / (1 + (g / scale)²)``, g the image's relative gradient at
    its tap (per pixel): ‖∂RGB/∂(u, v)‖ / ‖RGB‖ from its bilinear ``values`` (M, 3) and
    ``gradient`` (M, 3, 2), so an edge between two paints of one brightness counts too."""
    size = np.linalg.norm(values, axis=1)
    g = np.linalg.norm(gradient.reshape(len(gradient), -1), axis=1) / np.maximum(size, 1e-6)
    return np.asarray(1.0 / (1.0 + (g / scale) ** 2))


def edge_scale(vertices: np.ndarray, adjacency: sp.csr_array) -> np.ndarray:
    """Mean length of the edges at each vertex (l_i of eq. 16), metres."""
    coo = adjacency.tocoo()
    length = np.linalg.norm(vertices[coo.row] - vertices[coo.col], axis=1)
    total = np.bincount(coo.row, weights=length, minlength=len(vertices))
    deg = np.bincount(coo.row, minlength=len(vertices))
    mean = total / np.maximum(deg, 1)
    fallback = float(np.median(mean[deg > 0])) if np.any(deg > 0) else 1.0
    return np.where(deg > 0, mean, fallback)
