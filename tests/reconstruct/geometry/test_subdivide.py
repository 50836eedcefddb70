"""√3 subdivision: counts, orientation, Kobbelt's smoothing rule, boundaries, target density."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from core.errors import RigError
from reconstruct.geometry.subdivide import (
    beta,
    decimate,
    mean_edge,
    non_manifold_faces,
    sqrt3_step,
    steps_for,
    subdivide,
)


def test_closed_mesh_counts_and_topology() -> None:
    mesh = trimesh.creation.icosahedron()
    v, f = sqrt3_step(mesh.vertices, mesh.faces)
    assert len(f) == 3 * len(mesh.faces)
    assert len(v) == len(mesh.vertices) + len(mesh.faces)
    out = trimesh.Trimesh(v, f, process=False)
    assert out.is_watertight and out.is_winding_consistent
    assert out.euler_number == 2
    assert out.volume > 0  # outward orientation kept
    # a centroid joins 3 corners and 3 neighbouring centroids; old vertices keep valence
    valence = np.bincount(out.edges_unique.ravel())
    assert np.all(valence[len(mesh.vertices) :] == 6)
    assert np.all(valence[: len(mesh.vertices)] == 5)


def test_two_steps_triple_the_resolution() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=1)
    fine = subdivide(mesh, 2)
    assert len(fine.faces) == 9 * len(mesh.faces)
    ratio = mesh.edges_unique_length.mean() / fine.edges_unique_length.mean()
    assert 2.6 < ratio < 3.4


def test_smoothing_rule_on_one_vertex() -> None:
    mesh = trimesh.creation.icosahedron()
    v, _ = sqrt3_step(mesh.vertices, mesh.faces)
    ring = mesh.vertex_neighbors[0]
    n = len(ring)
    b = (4 - 2 * np.cos(2 * np.pi / n)) / (9 * n)
    expected = (1 - n * b) * mesh.vertices[0] + b * mesh.vertices[ring].sum(axis=0)
    np.testing.assert_allclose(v[0], expected, atol=1e-12)
    # centroids are inserted from the *old* positions
    np.testing.assert_allclose(v[len(mesh.vertices)], mesh.vertices[mesh.faces[0]].mean(0))


def test_beta_values() -> None:
    np.testing.assert_allclose(beta(np.array([6])), [1 / 18])  # (4 - 2 cos 60°) / 54
    np.testing.assert_allclose(beta(np.array([3])), [5 / 27])  # (4 + 1) / 27


def test_open_mesh_keeps_boundary() -> None:
    sphere = trimesh.creation.icosphere(subdivisions=2)
    keep = sphere.triangles_center[:, 2] < 0.5  # a bowl: the sphere without its cap
    grid = trimesh.Trimesh(sphere.vertices, sphere.faces[keep])
    single = trimesh.grouping.group_rows(grid.edges_sorted, require_count=1)
    boundary = np.unique(grid.edges[single])
    edges = grid.edges_unique
    n_boundary_edges = len(single)
    n_inner = len(edges) - n_boundary_edges
    v, f = sqrt3_step(grid.vertices, grid.faces)
    assert len(f) == 2 * n_inner + n_boundary_edges
    np.testing.assert_array_equal(v[boundary], grid.vertices[boundary])
    out = trimesh.Trimesh(v, f, process=False)
    assert out.is_winding_consistent
    interior = np.setdiff1d(np.arange(len(grid.vertices)), boundary)
    assert not np.allclose(v[interior], grid.vertices[interior])


def test_inconsistent_orientation_is_refused() -> None:
    mesh = trimesh.creation.icosahedron()
    faces = mesh.faces.copy()
    faces[0] = faces[0][::-1]
    with pytest.raises(RigError, match="oriented"):
        sqrt3_step(mesh.vertices, faces)


def test_steps_for_target_density() -> None:
    assert steps_for(1.0, 1.0, 100, 6, 10**6) == 0
    assert steps_for(1.0, 0.5, 100, 6, 10**6) == 2  # 1/√3 = 0.58 > 0.5, 1/3 < 0.5
    assert steps_for(1.0, 1e-6, 100, 6, 10**6) == 6
    assert steps_for(1.0, 1e-6, 100, 6, 1000) == 2  # 900 faces ok, 2700 too many


def test_a_mesh_finer_than_the_images_is_decimated_to_the_target() -> None:
    """A dense MVS mesh (here a noisy icosphere of 0.4 mm edges, radius 5 cm) is coarsened to
    just under the target edge, stays one edge-manifold piece that √3 can subdivide, and
    keeps its shape."""
    fine = trimesh.creation.icosphere(subdivisions=7, radius=0.05)
    rng = np.random.default_rng(0)
    fine.vertices += rng.normal(0, 2e-5, fine.vertices.shape)
    target = 2.5 * mean_edge(fine)
    coarse = decimate(fine, mean_edge(fine), target)
    assert 0.75 * target < mean_edge(coarse) < 1.25 * target
    assert len(coarse.vertices) < 0.25 * len(fine.vertices)
    assert not non_manifold_faces(coarse).any()
    radius = np.linalg.norm(coarse.vertices, axis=1)
    assert np.abs(radius - 0.05).max() < 2e-4
    sqrt3_step(coarse.vertices, coarse.faces)  # raises on a non-manifold mesh


def test_non_manifold_faces_are_found() -> None:
    tri = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, -1, 0]],
                          [[0, 1, 2], [1, 0, 3], [0, 1, 4]], process=False)
    assert non_manifold_faces(tri).tolist() == [True, True, True]  # edge 0-1 has 3 faces
    ok = trimesh.creation.icosphere(subdivisions=1)
    assert not non_manifold_faces(ok).any()
