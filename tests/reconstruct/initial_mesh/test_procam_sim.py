"""Projector sessions of the simulated rig, end to end: DNG frames -> Gray code -> mesh."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.config import from_mapping
from core.errors import RigError
from core.manifest import FrameRecord, append_manifest
from core.session import Session
from reconstruct.frames import decode
from reconstruct.initial_mesh.procam import (
    LIGHTS,
    SUMMARY,
    ProcamConfig,
    has_gray_code,
    procam_initial_mesh,
    read_light_positions,
)
from reconstruct.model.camera import read_colmap_text
from reconstruct.stages.resumable import STAMP
from tests.reconstruct.initial_mesh import sim_session


def _mean_distance_mm(mesh_path: Path, rig) -> tuple[float, int]:
    mesh = trimesh.load(mesh_path, force="mesh")
    truth = trimesh.Trimesh(rig.scene.vertices, rig.scene.faces, process=False)
    _, dist, _ = trimesh.proximity.closest_point(truth, mesh.vertices)
    return 1000.0 * float(dist.mean()), len(mesh.vertices)


@pytest.mark.slow
def test_placements_session_gives_accurate_mesh_and_lights(tmp_path: Path) -> None:
    root = tmp_path / "session"
    rig, poses = sim_session.capture(root, plate=False)
    session = Session.open(root)
    out = root / "recon" / "procam"
    mesh = procam_initial_mesh(session, dict(enumerate(poses)), sim_session.intrinsics(),
                               ProcamConfig(), out)
    mean_mm, n_vertices = _mean_distance_mm(mesh, rig)
    print(f"placements: mean distance to truth {mean_mm:.3f} mm, {n_vertices} vertices")
    assert mean_mm < 0.5 and n_vertices > 2000
    summary = json.loads((out / SUMMARY).read_text())
    assert summary["mode"] == "placements" and summary["points"] > 4000
    _, placement, projectors = sim_session.layout(plate=False)
    lights = read_light_positions(out)
    assert sorted(lights) == list(range(6))
    for view, position in lights.items():
        # the projector's optical centre, recovered by resection with an estimated focal
        assert np.linalg.norm(position - projectors[placement[view]].center) < 0.015
    for entry in summary["placements"].values():
        assert abs(entry["projector_focal_px"] - sim_session.PROJECTOR["focal_px"]) < 8.0
    # resumable: a second call with the same inputs is skipped
    stamp = (out / STAMP).stat().st_mtime_ns
    procam_initial_mesh(session, dict(enumerate(poses)), sim_session.intrinsics(),
                        ProcamConfig(), out)
    assert (out / STAMP).stat().st_mtime_ns == stamp


@pytest.mark.slow
def test_plate_session_from_decode_stage(tmp_path: Path) -> None:
    root = tmp_path / "session"
    rig, poses = sim_session.capture(root, plate=True)
    decoded = decode.run({"demosaic": "linear"}, root, root / "recon" / "decoded")
    session = Session.open(root)
    conf = {"projector_focal_px": sim_session.PROJECTOR["focal_px"]}
    out = root / "recon" / "procam"
    mesh = procam_initial_mesh(session, dict(enumerate(poses)), sim_session.intrinsics(),
                               conf, out, decoded_dir=decoded)
    mean_mm, n_vertices = _mean_distance_mm(mesh, rig)
    print(f"plate: mean distance to truth {mean_mm:.3f} mm, {n_vertices} vertices")
    assert mean_mm < 1.0 and n_vertices > 2000
    lights = read_light_positions(out)
    offset = np.array([-0.06, 0.0, 0.0])
    for view, pose in enumerate(poses):
        assert np.allclose(lights[view], pose.light_position(offset))
    assert json.loads((out / LIGHTS).read_text())["mode"] == "plate"
    assert has_gray_code(session)


def _fake_session(root: Path, labels: list[str], extra: dict) -> Session:
    (root / "raw").mkdir(parents=True)
    (root / "session.yaml").write_text("format: 1\n")
    for k, label in enumerate(labels):
        append_manifest(root, FrameRecord(k, 0, label, f"raw/{k}.npy", "0" * 64, 0.1, 100.0,
                                          "2026-01-01T00:00:00Z", extra))
    return Session.open(root)


def test_plate_mode_needs_offset_and_focal(tmp_path: Path) -> None:
    session = _fake_session(tmp_path / "s", ["gray-col-00", "gray-col-00-inv"], {})
    poses, _, _ = sim_session.layout(plate=True)
    with pytest.raises(RigError, match="light_mount.offset_m"):
        procam_initial_mesh(session, {0: poses[0]}, sim_session.intrinsics(), {}, tmp_path / "o")
    session.info = replace(session.info, light_offset_m=(0.05, 0.0, 0.0))
    with pytest.raises(RigError, match="projector_focal_px"):
        procam_initial_mesh(session, {0: poses[0]}, sim_session.intrinsics(), {}, tmp_path / "o")


def test_session_without_gray_code_is_refused(tmp_path: Path) -> None:
    session = _fake_session(tmp_path / "s", ["red", "green"], {"projector_placement": 0})
    poses, _, _ = sim_session.layout(plate=False)
    assert not has_gray_code(session)
    with pytest.raises(RigError, match="no Gray-code frames"):
        procam_initial_mesh(session, {0: poses[0]}, sim_session.intrinsics(),
                            {"mode": "placements"}, tmp_path / "o")


def test_unknown_mode_is_refused() -> None:
    with pytest.raises(RigError, match="procam.mode"):
        from_mapping(ProcamConfig, {"mode": "stereo"}, "config", "procam")


PROFILE = """\
name: projector-sim
description: sim camera + sim projector on the camera plate
devices:
  projector: {driver: sim}
  camera: {driver: sim}
camera_settings: {exposure_s: 0.5, iso: 100}
light_mount: {type: plate, offset_m: [-0.08, 0.0, 0.0]}
illuminations:
  red: {r: 1.0}
  full: {r: 1.0, g: 1.0, b: 1.0}
plan:
  views: 3
  illuminations: all
  ambient: false
  structured_light: {gray_code: true}
poses: known
sim:
  scene: blob
  subdivisions: 5
  camera: {width: 240, height: 180, focal_px: 500.0, supersample: 1}
  projector: {width: 128, height: 96, focal_px: 220.0}
"""


@pytest.mark.slow
def test_rig_capture_projector_session_end_to_end(tmp_path: Path) -> None:
    from rig.cli import main  # the user's path: `rig capture` with a projector profile

    profile = tmp_path / "projector-sim.yaml"
    profile.write_text(PROFILE)
    root = tmp_path / "session"
    assert main(["capture", "--profile", str(profile), "--out", str(root), "--yes"]) == 0
    cameras, images = read_colmap_text(root / "poses")
    poses = {iid - 1: pose for iid, (_, _, pose) in images.items()}
    intrinsics = {iid - 1: cameras[cid] for iid, (cid, _, _) in images.items()}
    mesh = procam_initial_mesh(Session.open(root), poses, intrinsics,
                               {"projector_focal_px": 220.0}, root / "recon" / "procam")
    m = trimesh.load(mesh, force="mesh")
    truth = trimesh.load(root / "ground_truth" / "mesh.ply", force="mesh")
    dist = trimesh.proximity.closest_point(truth, m.vertices)[1]
    print(f"rig capture (plate): mean distance {1000 * dist.mean():.3f} mm")
    assert 1000 * dist.mean() < 1.0 and len(m.vertices) > 2000
    lights = read_light_positions(root / "recon" / "procam")
    for view, pose in poses.items():
        assert np.allclose(lights[view], pose.light_position(np.array([-0.08, 0.0, 0.0])))
