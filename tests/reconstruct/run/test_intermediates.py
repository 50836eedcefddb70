"""Intermediates: their size per stage in report.json, the decoded frames deleted after a
successful export by default (kept with --keep-intermediates), and a later run that decodes
them again while every other front stage stays up to date."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from recon_tiny import make_session, reconstruct_args

from reconstruct.initial_mesh.dense.poisson import read_mesh
from rig.cli import main

pytest.importorskip("drivers.sim")
FRONT = ("poses", "initial_mesh", "visibility", "subdivide")


def frames_in(recon: Path) -> list[Path]:
    return sorted((recon / "decoded").glob("frame_*.npy"))


def test_frames_deleted_after_export_and_decoded_again_on_resume(tmp_path: Path) -> None:
    session, config = make_session(tmp_path)
    recon = session / "recon"
    assert main(reconstruct_args(session, config)) == 0
    report = json.loads((recon / "report.json").read_text())
    disk = report["intermediates_mb"]
    assert disk["stages"]["decoded"] > 0 and disk["decoded_frames_deleted"] > 0
    assert disk["left"] == pytest.approx(disk["total"] - disk["decoded_frames_deleted"], abs=0.2)
    assert frames_in(recon) == [] and (recon / "decoded" / "index.json").is_file()
    assert not list((recon / "decoded" / "sfm").glob("*"))
    assert not (recon / "decoded" / ".stamp.json").exists()  # decode must run again
    index_mtime = (recon / "decoded" / "index.json").stat().st_mtime_ns
    vertices = read_mesh(recon / "mesh.ply").vertices

    assert main([*reconstruct_args(session, config), "--keep-intermediates"]) == 0
    timings = json.loads((recon / "timings.json").read_text())
    assert not timings["decode"]["skipped"]
    assert all(timings[stage]["skipped"] for stage in FRONT), timings
    assert (recon / "decoded" / "index.json").stat().st_mtime_ns == index_mtime
    # the frames decoded again hash as before: the finished solve is resumed, not redone
    assert "resuming the optimisation" in (recon / "log.txt").read_text()
    np.testing.assert_allclose(read_mesh(recon / "mesh.ply").vertices, vertices, atol=1e-9)
    assert len(frames_in(recon)) == 2 * 16  # 16 frames: image and saturation mask each
    assert len(list((recon / "decoded" / "sfm").glob("*"))) == 8  # one per view
    report = json.loads((recon / "report.json").read_text())
    assert report["intermediates_mb"]["decoded_frames_deleted"] == 0
