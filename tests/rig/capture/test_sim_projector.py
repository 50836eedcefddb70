"""`rig capture` with free projector placements on the simulated rig, reconstructed by
reconstruct.initial_mesh.procam with no projector calibration."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from core.session import Session
from reconstruct.initial_mesh.procam import SUMMARY, procam_initial_mesh, read_light_positions
from reconstruct.model.camera import read_colmap_text
from rig.cli import main

PROFILE = Path(__file__).with_name("sim-projector-small.yaml")


@pytest.mark.slow
def test_captured_placements_session_gives_procam_mesh(tmp_path: Path) -> None:
    root = tmp_path / "session"
    assert main(["capture", "--profile", str(PROFILE), "--out", str(root), "--yes"]) == 0
    session = Session.open(root)
    assert {(f.view, f.extra["projector_placement"]) for f in session.frames} == {
        (v, v // 3) for v in range(6)
    }
    cameras, images = read_colmap_text(root / "poses")
    poses = {iid - 1: pose for iid, (_, _, pose) in images.items()}
    intrinsics = {iid - 1: cameras[cid] for iid, (cid, _, _) in images.items()}
    out = root / "recon" / "procam"
    mesh = trimesh.load(procam_initial_mesh(session, poses, intrinsics, {}, out), force="mesh")
    truth = trimesh.load(root / "ground_truth" / "mesh.ply", force="mesh")
    assert isinstance(mesh, trimesh.Trimesh) and isinstance(truth, trimesh.Trimesh)
    dist = trimesh.proximity.closest_point(truth, mesh.vertices)[1]
    print(
        f"procam mesh from rig capture (placements): mean distance {1000 * dist.mean():.3f} mm,"
        f" {len(mesh.vertices)} vertices"
    )
    assert 1000 * dist.mean() < 0.5 and len(mesh.vertices) > 2000
    summary = json.loads((out / SUMMARY).read_text())
    assert summary["mode"] == "placements" and set(summary["placements"]) == {"0", "1"}
    rig = yaml.safe_load((root / "ground_truth" / "rig.yaml").read_text())
    lights = read_light_positions(out)
    for view, position in lights.items():
        centre = rig["projector_placements"][rig["view_placement"][view]]["centre_m"]
        assert np.linalg.norm(position - np.asarray(centre)) < 0.015
