"""The working resolution end to end on the tiny sim session: decoded frames stored at a
level with the known cameras scaled to them, and `rig reconstruct --detail draft --edge-mm`
sampling the optimiser's frames a level down, with the levels in report.json."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from recon_tiny import PROFILE, make_session, reconstruct_args

from reconstruct.frames import decode
from reconstruct.frames.decode import DecodeIndex, load_frame
from reconstruct.frames.pyramid import downsample, downsample_mask
from reconstruct.model.camera import read_colmap_text
from reconstruct.poses import stage as poses
from reconstruct.poses.output import load as load_poses
from rig.cli import main

pytest.importorskip("drivers.sim")


def test_decode_stage_stores_the_level_and_known_cameras_follow(tmp_path: Path) -> None:
    session = tmp_path / "s"
    assert main(["capture", "--profile", str(PROFILE), "--out", str(session), "--yes"]) == 0
    out = session / "recon" / "decoded"
    linear = {"demosaic": "linear"}  # AHD reads dim blue ~9 % above the mosaic's own samples
    decode.run(linear, session, out, max_side=64)  # 128×96 frames: level 1
    index = DecodeIndex.load(out)
    assert {(f.level, f.width, f.height) for f in index.frames} == {(1, 64, 48)}
    image, sat = load_frame(out, index.frames[0])
    assert image.shape == (48, 64, 3) and sat.shape == (48, 64)
    poses.run({}, session, out, session / "recon" / "poses")
    posed = load_poses(session / "recon" / "poses")
    cams, _ = read_colmap_text(session / "poses")
    given = next(iter(cams.values()))
    for intr in posed.intrinsics.values():
        assert (intr.width, intr.height) == (64, 48)
        # pixel corners scale: focal and principal point halve exactly
        np.testing.assert_allclose(intr.K[:2], given.K[:2] / 2)
    # another preset decodes again (the level is part of the stage's settings)
    decode.run(linear, session, out, max_side=0)
    index = DecodeIndex.load(out)
    assert {f.level for f in index.frames} == {0}
    full, full_sat = load_frame(out, index.frames[0])
    lit = ~downsample_mask(full_sat, 1)
    np.testing.assert_allclose(image[lit].mean(0), downsample(full, 1)[lit].mean(0), rtol=0.01)
    assert sat[downsample_mask(full_sat, 1)].all()


def test_reconstruct_with_detail_and_edge_reports_the_levels(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    session, config = make_session(tmp_path)
    # 128×96 frames, focal 160 px at 0.5 m: 3.125 mm per pixel, a 10 mm edge spans 3.2 px
    assert main([*reconstruct_args(session, config), "--detail", "draft", "--edge-mm", "10"]) == 0
    recon = session / "recon"
    res = json.loads((recon / "report.json").read_text())["resolution"]
    assert res["detail"] == "draft"
    assert res["mm_per_px"] == pytest.approx(3.125, rel=1e-6)
    assert res["edge_mm"] == pytest.approx(10.0) and res["edge_px"] == pytest.approx(3.2)
    assert res["levels"] == {"decode": 0, "patchmatch": 2, "optimise": 1}
    assert res["sizes"] == {"decode": [128, 96], "patchmatch": [32, 24], "optimise": [64, 48]}
    assert json.loads((recon / "subdivide" / "subdivide.json").read_text())["target_edge"] == 0.01
    assert "optimiser 1 (64×48)" in capsys.readouterr().err
