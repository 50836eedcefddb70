"""Vertex normals and their Jacobian, adjacency."""

from __future__ import annotations

import numpy as np
import trimesh

from reconstruct.model.render import vertex_normals as render_normals
from reconstruct.optimise.mesh import (
    NormalJacobian,
    adjacency,
    edges,
    normal_jacobian,
    vertex_normals,
)


def test_normals_match_renderer_and_point_outward() -> None:
    m = trimesh.creation.icosphere(2)
    n, length = vertex_normals(m.vertices, m.faces)
    assert np.allclose(n, render_normals(np.asarray(m.vertices), np.asarray(m.faces)))
    assert np.all(np.einsum("ij,ij->i", n, m.vertices) > 0.99)
    assert np.all(length > 0)


def test_normal_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(0)
    m = trimesh.creation.icosphere(1)
    X = np.asarray(m.vertices) + 0.05 * rng.normal(size=m.vertices.shape)
    D = normal_jacobian(X, m.faces).toarray()
    h = 1e-6
    fd = np.zeros_like(D)
    for j in range(X.size):
        d = np.zeros(X.size)
        d[j] = h
        plus, _ = vertex_normals(X + d.reshape(-1, 3), m.faces)
        minus, _ = vertex_normals(X - d.reshape(-1, 3), m.faces)
        fd[:, j] = ((plus - minus) / (2 * h)).ravel()
    assert np.abs(D - fd).max() < 1e-6 * np.abs(D).max()
    # Only the 1-ring: the block (i, j) is zero unless j is i or a neighbour.
    adj = adjacency(m.faces, len(X)).toarray() + np.eye(len(X))
    blocks = np.abs(D).reshape(len(X), 3, len(X), 3).sum(axis=(1, 3))
    assert np.all(blocks[adj == 0] == 0)


def test_adjacency_is_symmetric_and_edges_unique() -> None:
    m = trimesh.creation.icosphere(1)
    a = adjacency(m.faces, len(m.vertices))
    assert (a != a.T).nnz == 0
    assert a.diagonal().sum() == 0
    e = edges(a)
    assert np.all(e[:, 0] < e[:, 1])
    assert len(e) == len(m.edges_unique)


def test_normal_jacobian_is_reusable_and_keeps_isolated_vertices() -> None:
    """One sparsity serves every evaluation; an unreferenced vertex gets an explicit zero
    diagonal block (its normal is the constant +z), so operators sharing the sparsity
    (the geometric term's Jacobian) still have a place for it."""
    rng = np.random.default_rng(3)
    m = trimesh.creation.icosphere(1)
    X = np.vstack([np.asarray(m.vertices), [[2.0, 0.0, 0.0]]])
    nj = NormalJacobian(m.faces, len(X))
    for _ in range(2):
        X = X + 0.02 * rng.normal(size=X.shape)
        D = nj(X).toarray()
        assert np.allclose(D, normal_jacobian(X, m.faces).toarray())
        assert np.array_equal(D[-3:], np.zeros((3, 3 * len(X))))
    last = len(X) - 1
    assert nj.block_row[-1] == last and nj.block_col[-1] == last
    assert nj.indptr[-1] - nj.indptr[-2] == 1
