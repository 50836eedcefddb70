"""The sim's ground plane: a printed ChArUco board the object stands on, rendered with the
forward model, from which the board module recovers the camera pose."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import RigError
from drivers.sim import SimRig
from reconstruct.model.camera import Pose, project
from reconstruct.model.render import GroundPlane
from reconstruct.poses.board import (
    BoardSpec,
    board_poses,
    board_texture,
    detect_board,
    linear_to_u8,
)

BOARD = BoardSpec.fit_paper("A3")  # 10x7 squares of 39 mm, as profiles/sim.yaml


def _uniform_ground(n: int) -> dict[str, object]:
    return {
        "texture": np.ones((4, 4)),
        "extent": [-0.3, -0.3, 0.3, 0.3],
        "paper": 0.8,
        "ink": np.full(n, 0.04),
    }


def test_plane_intersection_and_bilinear_sampling() -> None:
    ramp = np.tile(np.arange(8.0) / 7, (4, 1))  # value grows with x, texel centres known
    plane = GroundPlane(ramp, (0.0, 0.0, 0.8, 0.4), np.ones(3), np.zeros(3))
    # texel c has its centre at x = 0.05 + 0.1 c: between centres the sample is linear in x
    xy = np.array([[0.05, 0.2], [0.10, 0.1], [0.42, 0.3], [0.79, 0.05]])
    np.testing.assert_allclose(plane.sample(xy), [0.0, 0.5 / 7, 3.7 / 7, 1.0])
    down = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.6, 0.0, -0.8]])
    t = plane.intersect(np.array([0.1, 0.1, 1.0]), down)
    assert t[0] == pytest.approx(1.0) and np.isinf(t[1])  # upward ray misses
    assert np.isinf(t[2])  # lands at x = 0.85, beyond the quad
    with pytest.raises(RigError, match="ground texture"):
        GroundPlane(np.ones(5), (0.0, 0.0, 1.0, 1.0), np.ones(3), np.zeros(3))


def test_object_stands_on_the_ground_and_casts_its_shadow() -> None:
    plain = SimRig({"subdivisions": 4, "views": 2}, seed=0)
    rig = SimRig(
        {
            "subdivisions": 4,
            "views": 2,
            "camera": {"width": 160, "height": 120, "focal_px": 150.0},
            "ground": _uniform_ground(len(plain.scene.wavelengths)),
        },
        seed=0,
    )
    assert rig.scene.vertices[:, 2].min() == pytest.approx(0.0)
    lo, hi = rig.scene.vertices.min(axis=0), rig.scene.vertices.max(axis=0)
    np.testing.assert_allclose(rig.trajectory.target_m, (lo + hi) / 2)
    rig.camera.set_pose(Pose.look_at(np.array([0.0, -0.2, 0.55]), np.zeros(3)))
    rig.light.set_illumination(next(iter(rig.light.illuminations)))
    centre = (lo + hi) / 2
    light = np.array([0.3, 0.0, 0.15])  # low from +x: the shadow falls towards -x
    behind = light + (centre - light) * light[2] / (light[2] - centre[2])  # on the ground
    lit = np.array([0.15, -0.15, 0.0])
    (us, vs), (ul, vl) = project(rig.camera.intrinsics, rig.camera.pose, np.stack([behind, lit]))
    images = []
    for position in (light, behind + [0.0, 0.0, 0.15]):  # beside the object, then above the spot
        rig.light.position = position
        images.append(rig.camera.render_linear().sum(axis=2))
    assert behind[2] == pytest.approx(0.0)
    shadowed, from_above = (image[int(vs), int(us)] for image in images)
    assert images[0][int(vl), int(ul)] > 0  # the ground beside the object is lit
    assert from_above > 0  # the spot is on the ground, in view
    assert shadowed < 0.02 * from_above  # and in the object's shadow
    coverage = rig.camera._view_hits().coverage()  # the mesh only, not the ground
    assert 0 < coverage.mean() < 0.5


def test_board_pose_from_a_sim_render_is_accurate() -> None:
    texture, extent = board_texture(BOARD, 6000.0)
    rig = SimRig(
        {
            "subdivisions": 4,
            "views": 6,
            "trajectory": {"radius_m": 0.55, "elevations_deg": [50]},
            "camera": {"width": 640, "height": 480, "focal_px": 800.0, "supersample": 3},
            "ground": {"texture": texture, "extent": list(extent)},
        },
        seed=0,
    )
    rig.light.set_illumination(next(iter(rig.light.illuminations)))
    detections, truth = {}, {}
    for view in (1, 4):
        rig.goto_view(view)
        image = linear_to_u8(rig.camera.render_linear())
        detections[view] = detect_board(image, BOARD)
        truth[view] = rig.poses[view]
        assert detections[view].n_corners >= 15
    result = board_poses(detections, rig.intrinsics, (640, 480))
    for view, pose in truth.items():
        found = result.poses[view]
        err_mm = 1000 * np.linalg.norm(found.center - pose.center)
        cos = np.clip((np.trace(found.R @ pose.R.T) - 1) / 2, -1, 1)
        print(
            f"view {view}: {detections[view].n_corners} corners, pose error {err_mm:.3f} mm,"
            f" {np.degrees(np.arccos(cos)):.4f}°"
        )
        assert err_mm < 1.0 and np.degrees(np.arccos(cos)) < 0.1


def test_bad_ground_config_is_refused() -> None:
    with pytest.raises(RigError, match="sim.ground"):
        SimRig({"subdivisions": 3, "ground": {"texture": np.ones((4, 4))}})
    with pytest.raises(RigError, match="sim.ground.paper"):
        SimRig(
            {
                "subdivisions": 3,
                "ground": {"texture": np.ones((4, 4)), "extent": [0, 0, 1, 1], "paper": [0.5, 0.5]},
            }
        )
    with pytest.raises(RigError, match="sim.ground"):
        SimRig(
            {"subdivisions": 3, "ground": {"texture": "/nonexistent.npy", "extent": [0, 0, 1, 1]}}
        )


def test_shadow_rays_are_skipped_only_where_nothing_can_block() -> None:
    from reconstruct.model.render import _segment_meets_box

    rng = np.random.default_rng(0)
    lo, hi = np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])
    points, end = rng.uniform(-3, 3, (4000, 3)), rng.uniform(-3, 3, 3)
    meets = _segment_meets_box(points, end, lo, hi)
    along = points[None] + np.linspace(0, 1, 1001)[:, None, None] * (end - points)[None]
    sampled = np.all((along >= lo) & (along <= hi), axis=2).any(axis=0)
    assert not np.any(sampled & ~meets)  # never skips a segment that enters the box
    assert np.mean(meets & ~sampled) < 1e-3  # and tests little more than needed
    axis = np.array([[2.0, 0.0, 0.0], [0.5, 0.5, 3.0]])
    assert _segment_meets_box(axis, np.array([-2.0, 0.0, 0.0]), lo, hi).tolist() == [True, False]


def test_the_chart_lies_on_the_ground_as_a_card_that_the_camera_sees() -> None:
    n = len(SimRig({"subdivisions": 1, "views": 1}, seed=0).scene.wavelengths)
    rig = SimRig(
        {
            "scene": "chart",
            "views": 1,
            "camera": {"width": 160, "height": 120, "focal_px": 300.0},
            "ground": _uniform_ground(n),
        },
        seed=0,
    )
    assert rig.scene.vertices[:, 2].min() > 0  # above the ground's plane, not in it
    rig.camera.set_pose(Pose.look_at(np.array([0.0, -0.05, 0.4]), np.zeros(3)))
    hits = rig.camera._view_hits()
    assert hits.on_ground is not None
    patch = rig.scene.patch[hits.vertex_index[~hits.on_ground].ravel()]
    assert len(set(patch[patch >= 0].tolist())) == 24  # every patch seen, none hidden by paper
