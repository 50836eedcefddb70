"""Visibility V(i): frustum, front-facing, occlusion by other geometry; shadow masks; CSR."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from reconstruct.geometry.visibility import (
    Visibility,
    compute_visibility,
)
from reconstruct.model.camera import Intrinsics, Pose


def _scene() -> tuple[trimesh.Trimesh, int]:
    back = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    front = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    front.apply_translation([0.0, 0.0, 0.3])
    both = trimesh.Trimesh(
        np.vstack([back.vertices, front.vertices]),
        np.vstack([back.faces, front.faces + len(back.vertices)]),
    )
    return both, len(back.vertices)


def test_front_facing_and_occlusion(tmp_path: Path) -> None:
    mesh, n_back = _scene()
    intr = Intrinsics.pinhole(200, 200, 300.0)
    above = Pose.look_at(np.array([0.0, 0.0, 1.0]), np.zeros(3), up=(0.0, 1.0, 0.0))
    side = Pose.look_at(np.array([1.0, 0.0, 0.0]), np.zeros(3))
    vis = compute_visibility(mesh, {0: intr, 5: intr}, {0: above, 5: side})
    assert list(vis.views) == [0, 5]
    v = np.asarray(mesh.vertices)
    seen_above = np.array([0 in vis.of(i) for i in range(len(v))])
    seen_side = np.array([5 in vis.of(i) for i in range(len(v))])
    back = np.arange(len(v)) < n_back
    # the small sphere hides the top of the big one from the camera above
    hidden = back & (v[:, 2] > 0.09) & (np.hypot(v[:, 0], v[:, 1]) < 0.02)
    assert hidden.any() and not seen_above[hidden].any()
    # far sides are never visible
    assert not seen_above[back & (v[:, 2] < -0.01)].any()
    assert not seen_side[back & (v[:, 0] < -0.01)].any()
    # the side camera sees the big sphere's equator facing it
    facing = back & (v[:, 0] > 0.09)
    assert seen_side[facing].all()
    # depths are z in the camera frame
    rows, cols = vis.pairs()
    z = np.where(vis.views[cols] == 0, above.to_camera(v[rows])[:, 2],
                 side.to_camera(v[rows])[:, 2])
    np.testing.assert_allclose(vis.depth, z)
    path = tmp_path / "v.npz"
    vis.save(path)
    again = Visibility.load(path)
    np.testing.assert_array_equal(again.indptr, vis.indptr)
    np.testing.assert_array_equal(again.indices, vis.indices)


def test_out_of_frustum_is_not_visible() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    intr = Intrinsics.pinhole(40, 40, 30.0)  # narrow view
    pose = Pose.look_at(np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), up=(0.0, 1.0, 0.0))
    vis = compute_visibility(mesh, {0: intr}, {0: pose})
    assert vis.counts().sum() == 0


def test_the_optimisers_matrix_has_one_column_per_requested_view() -> None:
    # vertex 0 seen by views 2 and 7, vertex 1 by none, vertex 2 by view 7
    vis = Visibility(np.array([0, 2, 2, 3]), np.array([0, 1, 1]), np.zeros(3), np.array([2, 7]))
    matrix = vis.matrix([7, 3, 2])
    assert matrix.dtype == bool and matrix.shape == (3, 3)
    assert matrix.tolist() == [[True, False, True], [False, False, False], [True, False, False]]
