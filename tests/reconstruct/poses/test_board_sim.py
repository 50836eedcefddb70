"""The poses stage on the simulated rig standing on a printed A3 ChArUco board (the sim's
ground plane, rendered by the forward model, real Bayer DNGs): board poses against the truth,
SfM merged in for the views given too few corners."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from core.files import sha256_file
from core.manifest import FrameRecord, append_manifest
from drivers.sim.rig import SimRig
from reconstruct.frames import decode
from reconstruct.model.camera import read_colmap_text
from reconstruct.poses import stage as poses
from reconstruct.poses.board import BoardSpec, board_texture
from reconstruct.poses.output import load as load_poses

SPEC = BoardSpec.fit_paper("A3")  # 10x7 squares of 39 mm, as profiles/sim.yaml


def sim_board_session(root: Path, views: int) -> Path:
    texture, extent = board_texture(SPEC, 6000.0)
    rig = SimRig({
        "views": views, "subdivisions": 4,
        "trajectory": {"radius_m": 0.55, "elevations_deg": [50, 65]},
        "camera": {"width": 640, "height": 480, "focal_px": 800.0, "supersample": 3},
        "ground": {"texture": texture, "extent": list(extent)},
    }, seed=0)
    root.mkdir(parents=True)
    intr = rig.intrinsics
    (root / "session.yaml").write_text(yaml.safe_dump({
        "rig": "sim", "board": SPEC.to_dict(),
        "intrinsics": {"model": intr.model, "width": intr.width, "height": intr.height,
                       "params": list(intr.params)},
    }))
    name = next(iter(rig.light.illuminations))
    rig.light.set_illumination(name)
    for view in range(views):
        rig.goto_view(view)
        shot = rig.camera.capture(root / "raw", f"v{view:03d}")
        append_manifest(root, FrameRecord(
            view, view, name, shot.paths[0].relative_to(root).as_posix(),
            sha256_file(shot.paths[0]), shot.exposure_s, shot.iso, shot.timestamp,
            dict(shot.extra)))
    rig.write_ground_truth(root / "truth")
    return root


def rotation_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(a @ b.T) - 1) / 2, -1.0, 1.0))))


@pytest.mark.slow
def test_sim_board_and_sfm_poses(tmp_path: Path) -> None:
    root = sim_board_session(tmp_path / "s", views=8)
    decode.run({}, root, root / "recon" / "decoded")
    # views with fewer than 20 corners get no board pose: SfM poses them in the board frame
    out = poses.run({"board_min_corners": 20}, root, root / "recon" / "decoded",
                    root / "recon" / "poses")
    _, found, summary = load_poses(out)
    _, truth = read_colmap_text(root / "truth" / "poses")
    assert summary.source == "board+sfm" and summary.scale == "metric"
    assert summary.registered == 8
    by_source: dict[str, list[tuple[float, float]]] = {"board": [], "sfm": []}
    for iid, (_, _, pose) in truth.items():
        v = iid - 1
        err = (1000 * float(np.linalg.norm(found[v].center - pose.center)),
               rotation_deg(found[v].R, pose.R))
        by_source[summary.views[str(v)]["source"]].append(err)
    for source, errs in by_source.items():
        if errs:
            mm, deg = np.max(errs, axis=0)
            print(f"sim board session: {len(errs)} views from {source}, worst "
                  f"{mm:.3f} mm, {deg:.4f} deg")
    assert len(by_source["board"]) >= 3 and by_source["sfm"]
    board_err = np.array(by_source["board"])
    assert board_err[:, 0].max() < 1.0 and board_err[:, 1].max() < 0.1
    sfm_err = np.array(by_source["sfm"])
    assert sfm_err[:, 0].max() < 3.0 and sfm_err[:, 1].max() < 0.3
