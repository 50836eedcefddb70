"""The run loop against fake devices: complete sessions, failures, stops, resume."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest
from fakes import PROFILE, fake_profile, fake_rig
from rich.console import Console

from core.errors import RigError
from core.manifest import MANIFEST_FILE, read_manifest, verify_frames
from core.session import Session
from rig.capture import CaptureStopped, run_capture
from rig.profile import parse_profile

QUIET = Console(quiet=True)


def capture(out: Path, **kwargs):
    kwargs.setdefault("open_rig", fake_rig())
    return run_capture(
        kwargs.pop("profile", fake_profile()), out, yes=True, console=QUIET, **kwargs
    )


def assert_complete(session_dir: Path, n_frames: int) -> None:
    records = read_manifest(session_dir)
    assert sorted(r.frame for r in records) == list(range(n_frames))
    assert verify_frames(session_dir, records) == []
    on_disk = sorted(p.name for p in (session_dir / "raw").iterdir() if p.is_file())
    assert on_disk == sorted(Path(r.path).name for r in records)


def test_full_capture_writes_a_valid_session(tmp_path: Path) -> None:
    rig = fake_rig()
    out = capture(tmp_path / "s", open_rig=rig)
    session = Session.open(out)
    assert_complete(out, 4 * 4)
    assert session.views() == [0, 1, 2, 3]
    assert [f.illumination for f in session.frames_of_view(2)] == ["ambient", "A", "B", "C"]
    assert session.info.plan.frames == 16
    assert session.info.devices["camera"]["serial"] == "C1"
    assert session.info.runs[0]["status"] == "complete"
    assert "numpy" in session.info.software
    # the light is switched once per frame (ambient = off) and off at the end
    light = rig.made["light"]
    assert light.log[:4] == [None, {"r": 1.0}, {"g": 1.0}, {"b": 0.5, "w": 0.5}]
    assert light.log[-1] is None


def test_camera_failure_leaves_a_resumable_session(tmp_path: Path) -> None:
    out = tmp_path / "s"
    with pytest.raises(RigError) as failure:
        capture(out, open_rig=fake_rig(fail_at=7))
    assert "camera" in str(failure.value) and "--resume" in str(failure.value)
    assert len(read_manifest(out)) == 6
    info = Session.open(out).info
    assert info.runs[0]["status"].startswith("failed")
    capture(out, resume=True)
    assert_complete(out, 16)
    assert [r["status"] for r in Session.open(out).info.runs][-1] == "complete"


def test_resume_repairs_a_torn_manifest_and_re_adopts_its_frame(tmp_path: Path) -> None:
    out = tmp_path / "s"
    with pytest.raises(RigError):
        capture(out, open_rig=fake_rig(fail_at=9))
    manifest = out / MANIFEST_FILE
    lines = manifest.read_bytes().splitlines(keepends=True)
    torn = lines[-1][: len(lines[-1]) // 2]  # the last append was cut by a kill
    manifest.write_bytes(b"".join(lines[:-1]) + torn)
    lost = json.loads(lines[-1])["path"]  # its file is now an orphan, re-adopted
    (out / "raw" / ".incoming" / "f00009.npy").write_bytes(b"half")
    capture(out, resume=True)
    assert_complete(out, 16)
    assert (out / lost).is_file()  # kept under its name
    assert not any((out / "raw" / ".incoming").iterdir())


def test_ctrl_c_finishes_the_frame_in_flight_and_resumes(tmp_path: Path) -> None:
    out = tmp_path / "s"
    # Python's own handler, or SIG_IGN where the test run was started in the background.
    handler_before = signal.getsignal(signal.SIGINT)

    def press_ctrl_c(record) -> None:  # a real SIGINT while frame 5 is being stored
        if record.frame == 5:
            os.kill(os.getpid(), signal.SIGINT)

    with pytest.raises(CaptureStopped) as stopped:
        capture(out, on_frame=press_ctrl_c)
    assert "resume with `rig capture --resume" in str(stopped.value)
    assert sorted(r.frame for r in read_manifest(out)) == list(range(6))
    assert Session.open(out).info.runs[0]["status"] == "stopped"
    assert signal.getsignal(signal.SIGINT) is handler_before  # the capture restored it
    capture(out, resume=True)
    assert_complete(out, 16)


def test_out_folder_with_a_session_is_refused(tmp_path: Path) -> None:
    out = capture(tmp_path / "s")
    with pytest.raises(RigError, match="--resume"):
        capture(out)


def test_resume_uses_the_snapshot_profile(tmp_path: Path) -> None:
    out = tmp_path / "s"
    with pytest.raises(RigError):
        capture(out, profile=fake_profile(views=2), open_rig=fake_rig(fail_at=3))
    capture(out, profile=fake_profile(views=9), resume=True)
    assert_complete(out, 2 * 4)


def test_exposure_checks_are_recorded_once_per_illumination(tmp_path: Path) -> None:
    out = capture(tmp_path / "s", open_rig=fake_rig(level=70000))  # clipped: saturates
    checks = Session.open(out).info.exposure_checks
    assert set(checks) == {"A", "B", "C"}
    assert "halve" in checks["A"]["suggestion"] or "quarter" in checks["A"]["suggestion"]


def test_reconstruct_flag_runs_the_pipeline_or_says_it_is_missing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import sys
    import types

    from rig.commands import capture as command

    monkeypatch.setitem(sys.modules, "reconstruct.run.pipeline", None)  # not installed
    with pytest.raises(RigError, match="reconstruct.run.pipeline"):
        command.reconstruct(tmp_path)
    calls: list[Path] = []
    fake = types.ModuleType("reconstruct.run.pipeline")
    fake.run_reconstruction = calls.append  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "reconstruct.run.pipeline", fake)
    assert command.reconstruct(tmp_path) == 0
    assert calls == [tmp_path]


def test_prompts_name_the_view_and_q_stops(tmp_path: Path) -> None:
    asked: list[str] = []

    def ask(text: str) -> str:
        asked.append(text)
        return "q" if len(asked) == 3 else ""

    with pytest.raises(CaptureStopped):
        run_capture(fake_profile(), tmp_path / "s", ask=ask, console=QUIET, open_rig=fake_rig())
    assert asked[0].startswith("Move the plate to view 0 (1/4)")
    assert "this view: azimuth" in asked[1]
    assert sorted(r.frame for r in read_manifest(tmp_path / "s")) == list(range(8))


def test_resume_never_deletes_a_folder_that_is_not_a_session(tmp_path: Path) -> None:
    folder = tmp_path / "photos"
    folder.mkdir()
    (folder / "holiday.jpg").write_bytes(b"precious")
    with pytest.raises(RigError, match="not a capture session"):
        capture(folder, resume=True)
    assert (folder / "holiday.jpg").read_bytes() == b"precious"
    with pytest.raises(RigError, match="not empty"):
        capture(folder)


def test_resume_after_a_kill_before_session_yaml_starts_afresh(tmp_path: Path) -> None:
    out = tmp_path / "s"
    (out / "raw" / ".incoming").mkdir(parents=True)  # what a kill during set-up leaves
    (out / "calibration").mkdir()
    capture(out, resume=True)
    assert_complete(out, 16)


def test_a_device_that_fails_to_open_creates_no_session(tmp_path: Path) -> None:
    def broken(profile, seed, ask):
        raise RigError("camera (gphoto2) failed to open: no camera found", "plug it in")

    with pytest.raises(RigError, match="no camera found"):
        capture(tmp_path / "s", open_rig=broken)
    assert not (tmp_path / "s").exists()


def test_a_missing_calibration_entry_leaves_no_folder_behind(tmp_path: Path) -> None:
    pytest.importorskip("calibration.store")
    profile = parse_profile(
        {**PROFILE, "calibration": {"store": "default", "camera": "No Such Camera"}}, "cal.yaml"
    )
    with pytest.raises(RigError, match="No Such Camera"):
        capture(tmp_path / "s", profile=profile)
    assert not (tmp_path / "s").exists()


def test_a_torn_download_is_captured_again(tmp_path: Path) -> None:
    rig = fake_rig(corrupt=lambda shot: shot in (3, 4))  # frame 2 fails twice, then works
    out = capture(tmp_path / "s", open_rig=rig)
    assert_complete(out, 16)
    assert rig.made["camera"].shots == 18
    with pytest.raises(RigError, match="frame 0 .* does not decode"):
        capture(tmp_path / "t", open_rig=fake_rig(corrupt=lambda shot: True))
    assert read_manifest(tmp_path / "t") == []


def test_real_profiles_hand_their_sections_to_the_driver_registry(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from fakes import FakeCamera, FakeLight

    from drivers import registry
    from rig.capture.devices import open_devices
    from rig.profile import load_profile

    specs: dict[str, dict] = {}

    def opener(kind, device):
        def open_(spec, shared):
            specs[kind] = dict(spec)
            return device

        return open_

    light = FakeLight()
    monkeypatch.setattr(registry, "open_light", opener("light", light))
    monkeypatch.setattr(registry, "open_camera", opener("camera", FakeCamera(light)))
    devices = open_devices(load_profile("dmx-gphoto2"), 0, None)
    assert devices.light is light and devices.names == {"camera": "gphoto2", "light": "dmx"}
    assert specs["light"]["transport"]["port"] == "/dev/ttyUSB0"
    assert specs["light"]["illuminations"]["mix"] == {"r": 0.5, "g": 0.5, "b": 0.5, "w": 0.5}
    assert specs["camera"]["settings"] == {"exposure_s": 0.02, "iso": 100}
    with pytest.raises(RigError, match="--yes"):  # a hand-switched light needs a person
        open_devices(load_profile("bulb-manual-handheld"), 0, None)
