"""Umeyama similarity and bringing SfM poses into the board frame."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from core.errors import RigError
from reconstruct.model.camera import Pose, project
from reconstruct.poses.board import (
    BoardPoseResult,
    Similarity,
    board_poses,
    merge_with_sfm,
    umeyama,
)

# board frame -> an arbitrary SfM frame (scale 1/0.37 as SfM units are arbitrary)
TO_SFM = Similarity(
    2.7,
    Rotation.from_euler("zyx", [40, -25, 70], degrees=True).as_matrix(),
    np.array([3.0, -1.0, 0.5]),
)


def test_umeyama_recovers_a_known_similarity_exactly() -> None:
    rng = np.random.default_rng(0)
    src = rng.normal(size=(7, 3))
    truth = Similarity(0.37, Rotation.random(random_state=1).as_matrix(), np.array([1.0, -2, 3]))
    fit = umeyama(src, truth.apply(src))
    assert fit.scale == pytest.approx(0.37, rel=1e-12)
    assert np.allclose(fit.R, truth.R, atol=1e-12)
    assert np.allclose(fit.t, truth.t, atol=1e-12)
    back = fit.inverse()
    assert np.allclose(back.apply(fit.apply(src)), src, atol=1e-12)


def test_umeyama_needs_three_points_off_a_line() -> None:
    line = np.outer(np.arange(5.0), [1.0, 2.0, 3.0])
    with pytest.raises(RigError, match="collinear"):
        umeyama(line, line)


def test_similarity_moves_a_camera_with_its_scene() -> None:
    """A camera and the points it sees, both carried by the similarity, give the same image."""
    pose = Pose.look_at(np.array([0.3, -0.4, 0.5]), np.zeros(3))
    points = np.random.default_rng(2).uniform(-0.1, 0.1, size=(20, 3))
    intrinsics = pytest.importorskip("reconstruct.model.camera").Intrinsics.pinhole(640, 480, 500.0)
    moved = TO_SFM.apply_pose(pose)
    assert np.allclose(moved.center, TO_SFM.apply(pose.center[None])[0])
    assert np.allclose(
        project(intrinsics, pose, points), project(intrinsics, moved, TO_SFM.apply(points))
    )


@pytest.fixture(scope="module")
def board_result(scene: Any, captured: tuple) -> BoardPoseResult[int]:
    _, detections = captured
    return board_poses(detections, scene.intrinsics, (1280, 960))


@pytest.fixture(scope="module")
def captured(scene: Any, render_view: Any, orbit: Any) -> tuple[list[Pose], dict]:
    from reconstruct.poses.board import detect_board

    rng = np.random.default_rng(21)
    truth = orbit(6, rng)
    detections = {
        i: detect_board(render_view(scene, pose, rng, occluder_m=0.04), scene.spec)
        for i, pose in enumerate(truth)
    }
    # View 6 sees a few corners only; view 7 sees none (the object fills it).
    glance = Pose.look_at(np.array([0.0, -0.45, 0.3]), np.array([0.5, 0.0, 0.0]))
    truth.append(glance)
    detections[6] = detect_board(render_view(scene, glance, rng, occluder_m=0.0), scene.spec)
    truth.append(Pose.look_at(np.array([0.0, -0.12, 0.1]), np.array([0.0, 0.0, 0.06])))
    return truth, detections


def test_merge_recovers_the_similarity_and_carries_sfm_only_views(
    board_result: BoardPoseResult[int], captured: tuple
) -> None:
    truth, _ = captured
    assert 6 in board_result.rejected and 0 < board_result.n_corners[6] < 6
    # SfM: the board's views in its own frame, plus views 6 and 7 the board did not pose.
    sfm = {k: TO_SFM.apply_pose(p) for k, p in board_result.poses.items()}
    sfm[6], sfm[7] = TO_SFM.apply_pose(truth[6]), TO_SFM.apply_pose(truth[7])
    merged = merge_with_sfm(board_result, sfm)
    back = merged.similarity
    assert back.scale == pytest.approx(1 / 2.7, rel=1e-9)
    assert np.allclose(back.R, TO_SFM.R.T, atol=1e-9)
    assert np.allclose(back.apply(TO_SFM.t[None]), 0.0, atol=1e-9)
    assert merged.alignment_outliers == []
    assert max(merged.alignment_residual_m.values()) < 1e-9
    assert max(merged.alignment_rotation_deg.values()) < 1e-6
    assert merged.source == {**dict.fromkeys(board_result.poses, "board"), 6: "sfm", 7: "sfm"}
    for key in (6, 7):
        assert np.allclose(merged.poses[key].R, truth[key].R, atol=1e-9)
        assert np.allclose(merged.poses[key].t, truth[key].t, atol=1e-9)
    for key in board_result.poses:
        assert merged.poses[key] is board_result.poses[key]
        assert merged.reprojection_px[key] == board_result.reprojection_px[key]
    # View 6's few corners check the carried pose; view 7 shows no corner to check.
    assert merged.reprojection_px[6] < 0.3
    assert np.isnan(merged.reprojection_px[7])
    summary = json.loads(json.dumps(merged.summary()))
    assert summary["views"]["7"] == {"source": "sfm", "reprojection_px": None}
    assert summary["views"]["0"]["source"] == "board"
    assert summary["sfm_to_board"]["scale"] == pytest.approx(1 / 2.7)
    board_summary = json.loads(json.dumps(board_result.summary()))
    assert board_summary["6"]["rejected"].startswith("too few board corners")
    assert board_summary["0"]["corners"] == board_result.n_corners[0]


def test_a_misregistered_sfm_view_is_left_out(board_result: BoardPoseResult[int]) -> None:
    sfm = {k: TO_SFM.apply_pose(p) for k, p in board_result.poses.items()}
    bad = next(iter(sfm))
    pose = sfm[bad]
    sfm[bad] = Pose(pose.R, pose.t + np.array([0.0, 0.3, 0.0]))
    merged = merge_with_sfm(board_result, sfm)
    assert merged.alignment_outliers == [bad]
    assert merged.similarity.scale == pytest.approx(1 / 2.7, rel=1e-9)
    assert merged.alignment_residual_m[bad] > 0.05


def test_merge_needs_three_shared_views(board_result: BoardPoseResult[int]) -> None:
    keys = list(board_result.poses)[:2]
    sfm = {k: TO_SFM.apply_pose(board_result.poses[k]) for k in keys}
    with pytest.raises(RigError, match="only 2 views are posed by both"):
        merge_with_sfm(board_result, sfm)
