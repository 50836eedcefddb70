"""Poses (and intrinsics) from rendered board views against the known truth."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from core.errors import RigError
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.poses.board import Detection, board_poses, detect_board

N_VIEWS = 12


def rotation_deg(a: Pose, b: Pose) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(a.R @ b.R.T) - 1) / 2, -1.0, 1.0))))


@pytest.fixture(scope="module")
def captured(
    scene: Any, render_view: Callable[..., np.ndarray], orbit: Callable[..., list[Pose]]
) -> tuple[list[Pose], dict[int, Detection]]:
    """12 views around an object standing on the board (1280x960, f = 1100 px, ~0.5 m),
    plus view 99 looking mostly past the board."""
    rng = np.random.default_rng(11)
    truth = orbit(N_VIEWS, rng)
    detections = {
        i: detect_board(render_view(scene, pose, rng, occluder_m=0.04), scene.spec)
        for i, pose in enumerate(truth)
    }
    glance = Pose.look_at(np.array([0.0, -0.45, 0.3]), np.array([0.5, 0.0, 0.0]))
    truth.append(glance)
    detections[99] = detect_board(render_view(scene, glance, rng, occluder_m=0.0), scene.spec)
    return truth, detections


def check_accuracy(
    result: Any, truth: list[Pose], mm: float, deg: float, n_views: int = N_VIEWS
) -> None:
    """Every one of the first ``n_views`` views posed, all poses within mm / degrees."""
    assert set(range(n_views)) <= set(result.poses)
    for key, pose in result.poses.items():
        expected = truth[-1] if key == 99 else truth[key]
        assert np.linalg.norm(pose.center - expected.center) < mm / 1000, key
        assert rotation_deg(pose, expected) < deg, key
        assert result.reprojection_px[key] < 0.2


def test_poses_with_known_intrinsics(scene: Any, captured: tuple) -> None:
    truth, detections = captured
    assert min(detections[i].n_corners for i in range(N_VIEWS)) >= 15
    result = board_poses(detections, scene.intrinsics, (1280, 960))
    assert result.intrinsics == scene.intrinsics
    assert result.intrinsics_source == "given"
    check_accuracy(result, truth, mm=1.0, deg=0.1)
    assert result.rms_px < 0.1
    # The glancing view sees too little of the board and says so.
    assert 99 in result.rejected and "too few board corners" in result.rejected[99]
    assert result.n_corners[99] == detections[99].n_corners


def test_intrinsics_from_the_board_views_alone(scene: Any, captured: tuple) -> None:
    truth, detections = captured
    result = board_poses(detections, None, (1280, 960))
    assert "estimated" in result.intrinsics_source
    f, cx, cy, k1, k2 = result.intrinsics.params
    true_f, _, true_cx, true_cy = scene.intrinsics.params
    assert f == pytest.approx(true_f, rel=2e-3)
    assert abs(cx - true_cx) < 2.0 and abs(cy - true_cy) < 2.0
    assert abs(k1) < 0.02 and abs(k2) < 0.1
    check_accuracy(result, truth, mm=1.5, deg=0.1)


def test_refining_a_wrong_focal_length(scene: Any, captured: tuple) -> None:
    truth, detections = captured
    wrong = Intrinsics("PINHOLE", 1280, 960, (1130.0, 1130.0, 652.3, 471.8))
    fixed = board_poses(detections, wrong, (1280, 960))
    # A 3 % focal error hides in the distance: the views move out by about 3 %.
    shift = [
        np.linalg.norm(fixed.poses[k].center) / np.linalg.norm(truth[k].center) - 1
        for k in range(N_VIEWS)
    ]
    assert np.median(shift) == pytest.approx(0.027, abs=0.01)
    refined = board_poses(detections, wrong, (1280, 960), refine_intrinsics=True)
    assert refined.intrinsics.params[0] == pytest.approx(1100.0, rel=2e-3)
    check_accuracy(refined, truth, mm=1.5, deg=0.1)


def test_a_wrong_corner_is_dropped(scene: Any, captured: tuple) -> None:
    truth, detections = captured
    det = detections[0]
    corners = det.corners.copy()
    corners[3] += (4.0, -3.0)  # a corner caught on the object's outline
    bad = dict(detections)
    bad[0] = replace(det, corners=corners)
    clean = board_poses(detections, scene.intrinsics, (1280, 960))
    result = board_poses(bad, scene.intrinsics, (1280, 960))
    assert result.outlier_corners[0] == clean.outlier_corners.get(0, 0) + 1
    check_accuracy(result, truth, mm=1.0, deg=0.1)


def test_bad_inputs(scene: Any, captured: tuple) -> None:
    _, detections = captured
    with pytest.raises(RigError, match="1280x960 images but the frames are 640x480"):
        board_poses({}, scene.intrinsics, (640, 480))
    with pytest.raises(RigError, match="view 0: board detected in a 1280x960 image"):
        board_poses({0: detections[0]}, None, (640, 480))
    with pytest.raises(RigError, match="need 4"):
        board_poses({k: detections[k] for k in (0, 1, 2)}, None, (1280, 960))


def test_a_distorted_lens(
    scene: Any, render_view: Callable[..., np.ndarray], orbit: Callable[..., list[Pose]]
) -> None:
    """COLMAP RADIAL distortion end to end: rendered through the lens, posed with it given,
    and recovered from the board views alone."""
    lens = Intrinsics("RADIAL", 800, 600, (700.0, 405.0, 296.0, -0.12, 0.05))
    distorted = replace(scene, intrinsics=lens)
    rng = np.random.default_rng(12)
    truth = orbit(8, rng, distance=0.4)
    detections = {
        i: detect_board(render_view(distorted, pose, rng, occluder_m=0.03), scene.spec)
        for i, pose in enumerate(truth)
    }
    given = board_poses(detections, lens, (800, 600))
    check_accuracy(given, truth, mm=1.0, deg=0.1, n_views=8)
    estimated = board_poses(detections, None, (800, 600))
    check_accuracy(estimated, truth, mm=1.5, deg=0.1, n_views=8)
    assert estimated.intrinsics.params[0] == pytest.approx(700.0, rel=3e-3)
    # k1 and k2 trade off against each other; the displacement they cause where the board
    # was seen must agree.
    uv = np.concatenate([d.corners for d in detections.values()])
    xy = lens.undistort((uv - lens.K[:2, 2]) / 700.0)
    shift_true = lens.distort(xy) - xy
    shift_est = estimated.intrinsics.distort(xy) - xy
    assert 700.0 * np.abs(shift_true - shift_est).max() < 0.5
