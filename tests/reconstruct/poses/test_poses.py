"""Poses: known poses matched to views, metric scale from known distances, clear errors;
SfM on real photographs (slow)."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from core.errors import RigError
from core.session import Session
from core.session_info import SessionInfo
from reconstruct.frames import decode
from reconstruct.model.camera import Intrinsics, Pose, read_colmap_text, write_colmap_text
from reconstruct.poses import output as poses_output
from reconstruct.poses import stage as poses
from reconstruct.poses.config import PosesConfig
from reconstruct.poses.known import view_of_name
from reconstruct.poses.sfm import metric_scale, rescale, run_sfm, session_intrinsics


def _run(root: Path) -> Path:
    decode.run({}, root, root / "recon" / "decoded")
    return poses.run({}, root, root / "recon" / "decoded", root / "recon" / "poses")


def test_known_poses(make_session: Callable[..., Path]) -> None:
    root = make_session(views=4, illuminations=("white",))
    out = _run(root)
    intr, pose_map, summary = poses_output.load(out)
    assert summary.source == "known" and summary.scale == "metric"
    assert summary.registered == summary.total == 4
    _, truth = read_colmap_text(root / "poses")
    for iid, (_, _, pose) in truth.items():
        np.testing.assert_allclose(pose_map[iid - 1].R, pose.R, atol=1e-12)
        np.testing.assert_allclose(pose_map[iid - 1].t, pose.t, atol=1e-12)
    assert intr[0].width == 160


def test_too_few_views_is_a_clear_error(make_session: Callable[..., Path]) -> None:
    root = make_session(views=4, illuminations=("white",))
    cams, images = read_colmap_text(root / "poses")
    write_colmap_text(root / "poses", cams, {k: images[k] for k in (1, 2)})
    with pytest.raises(RigError, match="only 2 of 4 views"):
        _run(root)


def test_view_names(make_session: Callable[..., Path]) -> None:
    session = Session.open(make_session(views=3, illuminations=("white",), known_poses=False))
    assert view_of_name("raw/v001_white.npy", session) == 1
    assert view_of_name("v002_white.npy", session) == 2
    assert view_of_name("v002_white", session) == 2
    assert view_of_name("view_0001.png", session) == 1
    assert view_of_name("2", session) == 2
    assert view_of_name("view_0007.png", session) is None


def test_metric_scale_from_known_distances() -> None:
    centres = {0: np.zeros(3), 1: np.array([2.0, 0.0, 0.0]), 2: np.array([0.0, 4.0, 0.0])}
    info = SessionInfo.from_mapping({"profile": {"known_distances": [
        {"views": [0, 1], "metres": 0.5}, {"views": [0, 2], "metres": 1.0}]}})
    assert metric_scale(info, centres) == pytest.approx(0.25)
    assert metric_scale(SessionInfo(), centres) is None
    with pytest.raises(RigError, match=r"session.yaml: `known_distances\[0\]`"):
        SessionInfo.from_mapping({"known_distances": [{"views": [0]}]})


def test_intrinsics_from_session_and_rescale() -> None:
    intr = session_intrinsics(SessionInfo.from_mapping({"camera": {"intrinsics": {
        "model": "PINHOLE", "width": 200, "height": 100, "params": [150, 150, 100, 50]}}}))
    assert intr == Intrinsics("PINHOLE", 200, 100, (150.0, 150.0, 100.0, 50.0))
    half = rescale(intr, 100, 50)
    assert half.params == (75.0, 75.0, 50.0, 25.0)
    with pytest.raises(RigError, match="session.yaml: `intrinsics`"):
        SessionInfo.from_mapping({"intrinsics": {"model": "PINHOLE"}})


@pytest.mark.slow
def test_sfm_registers_the_sceaux_castle(shared_data: Path, tmp_path: Path) -> None:
    src = shared_data / "multiview" / "sceaux_castle" / "images"
    names = []
    for path in sorted(src.glob("*.JPG")):
        image = cv2.imread(str(path))
        assert image is not None
        f = 1000 / max(image.shape[:2])
        small = cv2.resize(image, None, fx=f, fy=f, interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(tmp_path / f"{path.stem}.png"), small)
        names.append(f"{path.stem}.png")
    k = np.loadtxt(src / "K.txt")
    full = Intrinsics("PINHOLE", 2832, 2128, (k[0, 0], k[1, 1], k[0, 2], k[1, 2]))
    h, w = small.shape[:2]
    work = tmp_path / "work"
    work.mkdir()
    # photographs of a facade: COLMAP's usual upright SIFT suffices (and is 3x faster)
    conf = PosesConfig(max_features=4096, affine_sift=False)
    result = run_sfm(tmp_path, names, conf, work, rescale(full, w, h))
    assert len(result.cameras) >= 10
    assert result.mean_reprojection_error_px < 1.5
    centres = np.array([pose.center for _, pose in result.cameras.values()])
    assert np.linalg.norm(np.ptp(centres, axis=0)) > 0  # a real baseline, not one point
    shutil.rmtree(work)
    print(f"sceaux: {len(result.cameras)}/{len(names)} registered, mean reprojection error "
          f"{result.mean_reprojection_error_px:.3f} px, {len(result.points)} points")
    assert isinstance(next(iter(result.cameras.values()))[1], Pose)
