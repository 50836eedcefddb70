"""End to end on the simulated rig: `rig capture`, SIGKILL at random instants + resume,
`rig session verify/info`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from simrig import PROFILE, assert_complete

from core.manifest import read_manifest
from core.session import Session
from rig.cli import main

pytest.importorskip("drivers.sim")


def test_sim_capture_writes_a_valid_session(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "s"
    assert main(["capture", "--profile", str(PROFILE), "--out", str(out), "--yes"]) == 0
    assert_complete(out)
    session = Session.open(out)
    assert {f.illumination for f in session.frames} == {"ambient", "LED1", "LED2", "LED3"}
    assert (out / "calibration" / "index.yaml").is_file()
    assert (out / "ground_truth" / "mesh.ply").is_file()
    assert not (out / "poses").exists()  # poses: estimate (the default)
    assert session.info.devices["camera"]["driver"] == "sim"
    assert session.info.calibration.camera == "Canon EOS 5D Mark II"
    first = session.frames_of_view(1)[1]
    assert first.path.endswith(".dng") and first.exposure_s > 0
    import rawpy

    with rawpy.imread(str(out / first.path)) as raw:
        assert raw.raw_image_visible.shape == (48, 64)
    capsys.readouterr()
    assert main(["session", "verify", str(out)]) == 0
    assert "16 frames checked, 0 missing or corrupt" in capsys.readouterr().out
    assert main(["session", "info", str(out)]) == 0
    info = capsys.readouterr().out
    assert "4 of 4 planned" in info and "16 of 16 planned" in info and "sim" in info


def test_session_info_accepts_the_demo_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    demo = tmp_path / "demo-out"  # `rig demo --out demo-out` captures into demo-out/session
    session = demo / "session"
    assert main(["capture", "--profile", str(PROFILE), "--out", str(session), "--yes"]) == 0
    capsys.readouterr()
    assert main(["session", "info", str(demo)]) == 0
    assert "16 of 16 planned" in capsys.readouterr().out


def test_session_verify_reports_corrupt_and_missing_frames(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "s"
    assert main(["capture", "--profile", str(PROFILE), "--out", str(out), "--yes"]) == 0
    records = read_manifest(out)
    with open(out / records[3].path, "r+b") as handle:
        handle.seek(200)
        handle.write(b"\x00\xff")
    (out / records[7].path).unlink()
    capsys.readouterr()
    assert main(["session", "verify", str(out)]) == 1
    text = capsys.readouterr().out
    assert "hash mismatch" in text and f"frame {records[3].frame}" in text
    assert "missing" in text and f"frame {records[7].frame}" in text


def test_projector_rig_captures_colours_and_gray_code(tmp_path: Path) -> None:
    data = {
        "devices": {"projector": {"driver": "sim"}, "camera": {"driver": "sim"}},
        "illuminations": {"red": {"r": 1.0}, "rgb": {"r": 1.0, "g": 1.0, "b": 1.0}},
        "plan": {"views": 1, "structured_light": {"gray_code": True}},
        "sim": {
            "subdivisions": 3,
            "camera": {"width": 64, "height": 48, "focal_px": 80.0, "supersample": 1},
            "projector": {"width": 32, "height": 16, "focal_px": 40.0},
        },
    }
    profile = tmp_path / "projector.yaml"
    profile.write_text(yaml.safe_dump(data))
    out = tmp_path / "s"
    assert main(["capture", "--profile", str(profile), "--out", str(out), "--yes"]) == 0
    labels = [r.illumination for r in read_manifest(out)]
    assert labels[:4] == ["red", "rgb", "white", "black"]
    assert len(labels) == 2 + 2 + 2 * 5 + 2 * 4
    import rawpy

    def mean(label: str) -> float:
        record = next(r for r in read_manifest(out) if r.illumination == label)
        with rawpy.imread(str(out / record.path)) as raw:
            return float(raw.raw_image_visible.mean())

    black, white = mean("black"), mean("white")
    assert white > black + 50
    for bit in ("col-01", "col-02", "row-01", "row-02"):  # a stripe and its inverse light it all
        both = mean(f"gray-{bit}") + mean(f"gray-{bit}-inv") - 2 * black
        assert both == pytest.approx(white - black, rel=0.05)


def test_sim_camera_failing_mid_session_leaves_a_resumable_session(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from drivers.sim import SimCamera

    real = SimCamera.capture
    shots = {"n": 0}

    def flaky(self, out_dir, stem):  # the USB cable is pulled at the 6th shot
        shots["n"] += 1
        if shots["n"] == 6:
            raise OSError("[Errno 19] No such device")
        return real(self, out_dir, stem)

    monkeypatch.setattr(SimCamera, "capture", flaky)
    out = tmp_path / "s"
    assert main(["capture", "--profile", str(PROFILE), "--out", str(out), "--yes"]) == 2
    err = "".join(capsys.readouterr().err.split())
    assert "camera(sim)failed" in err and "--resume" in err
    assert len(read_manifest(out)) == 5
    monkeypatch.setattr(SimCamera, "capture", real)
    assert main(["capture", "--resume", str(out), "--yes"]) == 0
    assert_complete(out)


def test_known_poses_are_written_for_the_sim(tmp_path: Path) -> None:
    data = yaml.safe_load(PROFILE.read_text())
    data["poses"] = "known"
    data["plan"]["views"] = 2
    data["known_distances"] = {
        "light_offset_m": 0.1,
        "camera_pairs": [{"views": [0, 1], "metres": 2.0}],
    }
    profile = tmp_path / "known.yaml"
    profile.write_text(yaml.safe_dump(data))
    out = tmp_path / "s"
    args = ["capture", "--profile", str(profile), "--out", str(out), "--yes", "--note", "test"]
    assert main(args) == 0
    from reconstruct.model.camera import read_colmap_text

    cameras, images = read_colmap_text(out / "poses")
    assert len(images) == 2 and cameras[1].width == 64
    info = Session.open(out).info
    assert info.notes == "test"
    from reconstruct.poses.sfm import metric_scale

    centres = {v: np.zeros(3) + v for v in (0, 1)}  # reconstructed 1.732 apart
    assert metric_scale(info, centres) == pytest.approx(2.0 / np.sqrt(3))
    assert info.known_lengths == {"light_offset_m": 0.1}
