"""Vertex normals and their Jacobian, adjacency, tangential relaxation, held vertices carried
along."""

from __future__ import annotations

import numpy as np
import trimesh

from reconstruct.model.render import vertex_normals as render_normals
from reconstruct.optimise.mesh import (
    NormalJacobian,
    adjacency,
    boundary_vertices,
    carried_along,
    edges,
    normal_jacobian,
    relax_tangentially,
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


def _flipped_faces(vertices: np.ndarray, faces: np.ndarray) -> int:
    """Faces whose normal points into a sphere centred at the origin."""
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return int(np.sum(np.einsum("ij,ij->i", normal, tri.mean(axis=1)) < 0))


def test_relaxation_unfolds_slivers_and_keeps_the_surface() -> None:
    """Vertices pushed along the surface past their neighbours (what moving along stale normals
    does) fold triangles over; relaxing within the tangent planes unfolds them and leaves the
    points on the sphere."""
    sphere = trimesh.creation.icosphere(4)
    rng = np.random.default_rng(3)
    X = np.asarray(sphere.vertices, dtype=float)
    n = X / np.linalg.norm(X, axis=1, keepdims=True)
    shift = rng.normal(0.0, 0.02, X.shape)  # about 0.8 of an edge
    shift -= np.einsum("ij,ij->i", shift, n)[:, None] * n
    crumpled = X + shift
    crumpled /= np.linalg.norm(crumpled, axis=1, keepdims=True)
    faces = np.asarray(sphere.faces)
    assert _flipped_faces(crumpled, faces) > 50
    relaxed = relax_tangentially(crumpled, faces)
    assert _flipped_faces(relaxed, faces) == 0
    radius = np.linalg.norm(relaxed, axis=1)
    assert np.abs(radius - 1.0).max() < 5e-3  # along the surface, to first order (edge 0.075)


def test_relaxation_moves_only_movable_vertices_off_the_boundary() -> None:
    box = trimesh.creation.box().subdivide().subdivide()
    faces = np.asarray(box.faces)
    open_faces = faces[np.asarray(box.triangles_center)[:, 2] < 0.49]  # top face cut away
    X = np.asarray(box.vertices) + np.random.default_rng(0).normal(0.0, 0.01, box.vertices.shape)
    rim = boundary_vertices(open_faces, len(X))
    assert rim.sum() > 0 and not rim.all()
    movable = np.ones(len(X), bool)
    movable[:5] = False
    relaxed = relax_tangentially(X, open_faces, movable)
    still = rim | ~movable
    np.testing.assert_array_equal(relaxed[still], X[still])
    assert np.abs(relaxed[~still] - X[~still]).max() > 1e-4


def test_held_vertices_are_carried_along_with_the_surface_around_them() -> None:
    """A pit in a sphere whose middle is held: its rim moves out to the sphere, and the middle
    follows as the rim's harmonic extension instead of staying a pit; a held part of the mesh
    that touches no moved vertex keeps its own displacement, moved vertices keep theirs."""
    sphere = trimesh.creation.icosphere(4)
    X = np.asarray(sphere.vertices, dtype=float)
    pit = X[:, 2] > 0.9
    middle = X[:, 2] > 0.95
    start = X.copy()
    start[pit] *= 0.9
    target = X - start  # what the data would move each vertex by
    moved = ~middle
    d = carried_along(np.where(moved[:, None], target, 0.0), sphere.faces, moved)
    np.testing.assert_array_equal(d[moved], target[moved])
    end = start + d
    assert np.abs(np.linalg.norm(end[middle], axis=1) - 1.0).max() < 0.01  # was 0.1 deep
    lonely = trimesh.Trimesh(X[sphere.faces[0]] + 5.0, [[0, 1, 2]])
    both = trimesh.util.concatenate([sphere, lonely])
    own = np.zeros((len(both.vertices), 3))
    own[-3:] = 0.5
    moved_both = np.r_[np.ones(len(X), bool), np.zeros(3, bool)]
    np.testing.assert_array_equal(
        carried_along(own, both.faces, moved_both)[-3:], own[-3:]
    )


def test_examples_in_the_docstrings_run() -> None:
    import doctest

    import reconstruct.optimise.mesh

    assert doctest.testmod(reconstruct.optimise.mesh).failed == 0
