"""The poses stage on board sessions: metric, upright board poses against the truth, SfM
merged in for a view that does not see the board, SfM failure tolerated, source choice."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from board_synthetic import (
    HIDDEN,
    INTRINSICS,
    SPEC,
    build_board_session,
    fake_sfm,
    true_poses,
)

from core.config import from_mapping
from core.errors import RigError
from reconstruct.frames import decode
from reconstruct.model.camera import Pose, write_colmap_text
from reconstruct.poses import sfm as poses_sfm
from reconstruct.poses import stage as poses
from reconstruct.poses.board_sfm import sfm_neighbourhood
from reconstruct.poses.config import PosesConfig
from reconstruct.poses.output import PoseSummary
from reconstruct.poses.output import load as load_poses
from reconstruct.poses.sfm import SfmResult

TRUTH = true_poses()


@pytest.fixture(scope="module")
def board_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Rendered and decoded once; each test works on a copy."""
    root = build_board_session(tmp_path_factory.mktemp("board") / "session", TRUTH)
    decode.run({}, root, root / "recon" / "decoded")
    return root


@pytest.fixture
def session_copy(board_session: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(board_session, tmp_path / "board"))


def rotation_deg(a: Pose, b: Pose) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(a.R @ b.R.T) - 1) / 2, -1.0, 1.0))))


def _poses(root: Path, conf: dict[str, Any] | None = None) -> tuple[dict, PoseSummary]:
    out = poses.run(conf or {}, root, root / "recon" / "decoded", root / "recon" / "poses")
    intr, pose_map, summary = load_poses(out)
    return {v: (intr[v], pose_map[v]) for v in pose_map}, summary


def _errors(cameras: dict, views: list[int]) -> tuple[float, float]:
    mm = max(1000 * np.linalg.norm(cameras[v][1].center - TRUTH[v].center) for v in views)
    deg = max(rotation_deg(cameras[v][1], TRUTH[v]) for v in views)
    return float(mm), deg


def test_board_poses_are_metric_and_upright(session_copy: Path) -> None:
    cameras, summary = _poses(session_copy, {"board_with_sfm": False})
    board_views = [v for v in range(len(TRUTH)) if v != HIDDEN]
    mm, deg = _errors(cameras, board_views)
    print(f"board poses ({len(board_views)} views, 960x720): worst camera centre error "
          f"{mm:.3f} mm, worst rotation error {deg:.4f} deg, RMS corner error "
          f"{summary.mean_reprojection_error_px:.3f} px")
    assert mm < 1.0 and deg < 0.1
    assert summary.source == "board" and summary.scale == "metric"
    assert summary.registered_views == board_views and summary.unregistered_views == [HIDDEN]
    assert all(cameras[v][1].center[2] > 0.2 for v in board_views)  # z up: cameras above
    assert cameras[0][0] == INTRINSICS and summary.intrinsics_source == "board (given)"
    views = json.loads((session_copy / "recon" / "poses" / "poses.json").read_text())["views"]
    assert {views[str(v)]["source"] for v in board_views} == {"board"}
    assert all(0 < views[str(v)]["reprojection_px"] < 0.5 for v in board_views)
    assert views[str(HIDDEN)]["source"] == "none" and "board_rejected" in views[str(HIDDEN)]
    assert np.load(session_copy / "recon" / "poses" / "points3D.npy").shape == (0, 3)


def test_sfm_adds_the_view_the_board_misses(
    session_copy: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    points = np.random.default_rng(0).uniform(-0.05, 0.05, (50, 3))
    seen: list[Any] = []

    def sfm(*args: Any) -> SfmResult:
        seen.append(args[-1])  # the board's intrinsics are passed on, fixed
        return fake_sfm(TRUTH, points)

    monkeypatch.setattr(poses_sfm, "run_sfm", sfm)
    cameras, summary = _poses(session_copy)
    assert summary.source == "board+sfm" and summary.registered == len(TRUTH)
    assert seen == [INTRINSICS]
    mm, deg = _errors(cameras, [HIDDEN])
    print(f"SfM-only view carried into the board frame: {mm:.3f} mm, {deg:.4f} deg")
    assert mm < 2.0 and deg < 0.2
    assert summary.views[str(HIDDEN)]["source"] == "sfm"
    assert summary.views["0"]["source"] == "board"
    assert summary.views["0"]["alignment_residual_mm"] < 2.0
    assert summary.extra["sfm_to_board"]["scale"] == pytest.approx(1 / 2.5, rel=1e-3)
    moved = np.load(session_copy / "recon" / "poses" / "points3D.npy")
    assert np.abs(moved - points).max() < 2e-3  # SfM points brought into the board frame


def test_sfm_runs_beside_the_board_only_where_it_can_add_a_view(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = build_board_session(tmp_path / "all", TRUTH[:HIDDEN])  # every view sees the board
    decode.run({}, root, root / "recon" / "decoded")
    calls: list[int] = []

    def sfm(*_: Any) -> SfmResult:
        calls.append(1)
        return fake_sfm(TRUTH[:HIDDEN], np.zeros((5, 3)))

    monkeypatch.setattr(poses_sfm, "run_sfm", sfm)
    cameras, summary = _poses(root)  # auto
    assert calls == [] and summary.source == "board" and summary.registered == HIDDEN
    shutil.rmtree(root / "recon" / "poses")
    _, summary = _poses(root, {"board_with_sfm": True})  # the cross-check, asked for
    assert calls == [1] and summary.source == "board+sfm"
    with pytest.raises(RigError, match="board_with_sfm"):
        from_mapping(PosesConfig, {"board_with_sfm": "sometimes"}, "config", "poses")


def test_sfm_neighbourhood_of_the_unposed_views_in_capture_order() -> None:
    views = list(range(40))
    assert sfm_neighbourhood(views, [0, 39], 4) == [*range(5), *range(35, 40)]
    assert sfm_neighbourhood(views, [20], 2) == [18, 19, 20, 21, 22]


def test_sfm_beside_the_board_runs_on_the_hidden_views_neighbours(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    truth = true_poses(14)  # 14 views see the board, the 15th (14) looks past it
    root = build_board_session(tmp_path / "s", truth)
    decode.run({}, root, root / "recon" / "decoded")
    asked: list[list[str]] = []
    registers_hidden = [False, True]

    def sfm(image_dir: Path, names: list[str], *_: Any) -> SfmResult:
        asked.append(sorted(names))
        full = fake_sfm(truth, np.random.default_rng(0).uniform(-0.05, 0.05, (60, 3)))
        cameras = {n: c for n, c in full.cameras.items() if n in names}
        if not registers_hidden.pop(0):
            cameras.pop("view_0014.png")
        return SfmResult(cameras, full.points, full.mean_reprojection_error_px)

    monkeypatch.setattr(poses_sfm, "run_sfm", sfm)
    # the neighbourhood's model misses the hidden view: SfM of every view follows
    cameras, summary = _poses(root)
    assert [len(a) for a in asked] == [9, 15] and summary.views["14"]["source"] == "sfm"
    assert len(np.load(root / "recon" / "poses" / "points3D.npy")) == 60
    # the neighbourhood's model carries it: one small SfM; its one-sided points are dropped
    asked.clear()
    registers_hidden[:] = [True]
    shutil.rmtree(root / "recon" / "poses")
    cameras, summary = _poses(root)
    assert asked == [[f"view_{v:04d}.png" for v in (0, 1, 2, 3, 10, 11, 12, 13, 14)]]
    assert summary.source == "board+sfm" and summary.views["14"]["source"] == "sfm"
    mm = 1000 * np.linalg.norm(cameras[14][1].center - truth[14].center)
    assert mm < 2.0
    assert np.load(root / "recon" / "poses" / "points3D.npy").shape == (0, 3)


def test_failing_sfm_is_tolerated(session_copy: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def sfm(*_: Any) -> SfmResult:
        raise RigError("structure from motion registered no views", "texture")

    monkeypatch.setattr(poses_sfm, "run_sfm", sfm)
    cameras, summary = _poses(session_copy)
    assert summary.source == "board" and summary.registered == len(TRUTH) - 1
    assert "registered no views" in summary.extra["sfm_error"]


def test_intrinsics_estimated_from_the_board(tmp_path: Path) -> None:
    root = build_board_session(tmp_path / "s", TRUTH, intrinsics_in_yaml=False)
    decode.run({}, root, root / "recon" / "decoded")
    cameras, summary = _poses(root, {"board_with_sfm": False, "board_model": "PINHOLE"})
    intr = cameras[0][0]
    mm, deg = _errors(cameras, [v for v in range(len(TRUTH)) if v != HIDDEN])
    print(f"estimated intrinsics: f = {intr.params[0]:.1f} px (true {INTRINSICS.params[0]}), "
          f"pose errors {mm:.3f} mm, {deg:.4f} deg")
    assert summary.intrinsics_source.startswith("board (estimated")
    assert intr.params[0] == pytest.approx(INTRINSICS.params[0], rel=0.01)
    assert mm < 1.0 and deg < 0.1


def test_source_choice_and_errors(
    session_copy: Path, make_session: Callable[..., Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    with pytest.raises(RigError, match="poses.source"):
        from_mapping(PosesConfig, {"source": "lidar"}, "config", "poses")
    with pytest.raises(RigError, match="poses.source is known"):
        _poses(session_copy, {"source": "known"})
    plain = make_session(views=4, illuminations=("white",), known_poses=False)
    decode.run({}, plain, plain / "recon" / "decoded")
    with pytest.raises(RigError, match="no board entry"):
        _poses(plain, {"source": "board"})
    # no board in the session: auto runs SfM, as before
    calls: list[str] = []

    def sfm(image_dir: Path, names: list[str], *_: Any) -> SfmResult:
        calls.append(str(image_dir))
        return SfmResult({}, np.zeros((0, 3)), 0.0)

    monkeypatch.setattr(poses_sfm, "run_sfm", sfm)
    with pytest.raises(RigError, match=r"only 0 of 4 views .*\(sfm\)"):
        _poses(plain)
    assert len(calls) == 1
    # a board that poses too few views and no SfM: a clear error naming both
    monkeypatch.setattr(
        poses_sfm, "run_sfm", lambda *_: (_ for _ in ()).throw(RigError("SfM found nothing", "x"))
    )
    with pytest.raises(RigError, match="board posed only .* SfM failed: SfM found nothing"):
        _poses(session_copy, {"board_min_corners": 500})


def test_board_found_in_full_resolution_frames_when_sfm_copies_are_small(
    session_copy: Path,
) -> None:
    """Downscaled SfM copies would cost the corners their sub-pixel accuracy: the board is
    then detected in the linear frames."""
    decoded = session_copy / "recon" / "decoded"
    shutil.rmtree(decoded)
    decode.run({"sfm_max_side": 480}, session_copy, decoded)
    cameras, summary = _poses(session_copy, {"board_with_sfm": False})
    mm, deg = _errors(cameras, [v for v in range(len(TRUTH)) if v != HIDDEN])
    assert summary.registered == len(TRUTH) - 1 and mm < 1.0 and deg < 0.1


def test_board_frame_poses_send_the_board_to_the_mesh_stage(session_copy: Path) -> None:
    """The silhouettes of a board session are cut against the board's print (no dark
    background), which the initial-mesh stage needs the board for."""
    from core.session import Session
    from reconstruct.initial_mesh.stage import MeshConfig
    from reconstruct.run.front import _mesh_config

    _, summary = _poses(session_copy, {"board_with_sfm": False})
    session = Session.open(session_copy)
    conf = _mesh_config(MeshConfig(), session, summary)
    assert conf.board_spec() == SPEC
    # known poses win in auto; they are in the board frame when its corners agree with them
    for shift, in_frame in ((0.0, True), (0.05, False)):
        write_colmap_text(
            session_copy / "poses", {1: INTRINSICS},
            {v + 1: (1, f"view_{v:04d}", Pose(p.R, p.t + shift)) for v, p in enumerate(TRUTH)},
        )
        _, summary = _poses(session_copy)
        assert summary.source == "known" and summary.extra["board_frame"] is in_frame
        conf = _mesh_config(MeshConfig(), session, summary)
        assert (conf.board_spec() == SPEC) is in_frame
    assert summary.views["0"]["reprojection_px"] > 10  # the shifted poses miss the corners
