"""Cleaning a triangulated point cloud and the mesh made from it: outliers out, PCA normals
facing the cameras, and mesh parts far from the cloud (invented by Poisson) or in small
pieces cut away."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from core.errors import RigError


def oriented_normals(points: np.ndarray, towards: np.ndarray, k: int) -> np.ndarray:
    """PCA normals over ``k`` neighbours, flipped to face ``towards`` (directions to cameras)."""
    _, idx = cKDTree(points).query(points, k=min(k, len(points)))
    nb = points[idx] - points[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    normals = np.linalg.eigh(cov)[1][:, :, 0]
    flip = np.einsum("ij,ij->i", normals, towards) < 0
    normals[flip] *= -1
    return normals


def drop_outliers(points: np.ndarray, k: int = 8, factor: float = 3.0) -> np.ndarray:
    """Mask of points whose k-th neighbour is within ``factor`` x the median such distance."""
    d = cKDTree(points).query(points, k=min(k + 1, len(points)))[0][:, -1]
    return np.asarray(d <= factor * np.median(d))


def keep_large_pieces(mesh: trimesh.Trimesh, fraction: float) -> trimesh.Trimesh:
    """Drop connected pieces with fewer than ``fraction`` of the faces (labels from
    ``scipy.sparse.csgraph``: trimesh's ``split`` needs networkx, not a dependency)."""
    n = len(mesh.vertices)
    edges = mesh.edges_unique
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    face_label = labels[mesh.faces[:, 0]]
    counts = np.bincount(face_label)
    keep = counts[face_label] >= fraction * len(mesh.faces)
    out = mesh.submesh([np.nonzero(keep)[0]], append=True)
    assert isinstance(out, trimesh.Trimesh)
    return out


def trim_to_cloud(mesh: trimesh.Trimesh, points: np.ndarray, factor: float) -> trimesh.Trimesh:
    """Cut faces whose vertices all lie farther than ``factor`` point spacings from the cloud
    (Poisson closes open scans with invented surface), then drop small leftover pieces."""
    tree = cKDTree(points)
    spacing = float(np.median(tree.query(points, k=2)[0][:, 1]))
    far = tree.query(mesh.vertices)[0] > factor * spacing
    keep = ~np.all(far[mesh.faces], axis=1)
    if not keep.any():
        raise RigError("trimming removed the whole mesh", "raise procam.trim_distance")
    out = mesh.submesh([np.nonzero(keep)[0]], append=True)
    assert isinstance(out, trimesh.Trimesh)
    return keep_large_pieces(out, 0.05)
