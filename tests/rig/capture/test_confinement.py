"""Paths read from files stay where they belong: calibration index `file:` entries inside the
store, manifest `path` entries inside the session — else one clear error and nothing touched."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from calibration.store import CalibrationStore
from core.errors import RigError
from rig.capture.trust import confirm_session_devices, session_programs
from rig.cli import main
from rig.profile import parse_profile

ROOT = Path(__file__).parents[3]


def make_store(root: Path) -> Path:
    store = CalibrationStore(root)
    w = np.arange(400.0, 701.0, 10.0)
    store.add_light("LED1", w, np.ones_like(w), {"source": "test"})
    return root


def point_entry_at(store: Path, file: str) -> None:
    index = store / "index.yaml"
    data = yaml.safe_load(index.read_text())
    data["entries"][0]["file"] = file
    index.write_text(yaml.safe_dump(data, sort_keys=False))


@pytest.fixture
def victim(tmp_path: Path) -> Path:
    path = tmp_path / "victim.csv"
    path.write_text("precious\n")
    return path


@pytest.mark.parametrize("how", ["dotdot", "absolute", "symlink"])
def test_a_store_entry_outside_the_store_is_refused_and_never_removed(
    tmp_path: Path, victim: Path, how: str, capsys: pytest.CaptureFixture[str]
) -> None:
    store = make_store(tmp_path / "a" / "store")
    if how == "dotdot":
        file = "../../victim.csv"
    elif how == "absolute":
        file = str(victim)
    else:
        os.symlink(victim, store / "lights" / "link.csv")
        file = "lights/link.csv"
    point_entry_at(store, file)
    code = main(["calibrate", "remove", "LED1", "--all", "--store", str(store)])
    err = " ".join(capsys.readouterr().err.split())
    assert code == 2 and victim.read_text() == "precious\n"
    assert "index.yaml: entry 'LED1' v1 has file:" in err and "not a file inside the store" in err
    with pytest.raises(RigError, match="not a file inside the store"):
        CalibrationStore(store)


def test_capture_with_such_a_store_writes_nothing_outside_the_session(
    tmp_path: Path, victim: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("drivers.sim")
    store = make_store(tmp_path / "store")
    point_entry_at(store, "../victim.csv")
    profile = yaml.safe_load((ROOT / "tests/rig/sim-small.yaml").read_text())
    profile["calibration"] = {"store": str(store), "camera": "x", "lights": {"LED1": "LED1"}}
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(profile))
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main(["capture", "--yes", "--profile", str(path), "--out", str(tmp_path / "s")])
    assert code == 2 and "not a file inside the store" in " ".join(capsys.readouterr().err.split())
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no session, nothing beside
    assert victim.read_text() == "precious\n"


def session_with_path(tmp_path: Path, path: str) -> Path:
    session = tmp_path / "s"
    (session / "raw").mkdir(parents=True)
    (session / "session.yaml").write_text(yaml.safe_dump({"plan": {"views": 2, "frames": 2}}))
    line = {
        "frame": 0,
        "view": 0,
        "illumination": "LED1",
        "path": path,
        "sha256": "0" * 64,
        "exposure_s": 1.0,
        "iso": 100.0,
        "timestamp": "2026-01-01T00:00:00+00:00",
    }
    (session / "manifest.jsonl").write_text(json.dumps(line) + "\n")
    return session


@pytest.mark.parametrize(
    "path", ["../../etc/passwd", "/etc/passwd", "raw/../../x.dng", "C:\\frames\\a.dng"]
)
def test_manifest_paths_outside_the_session_are_refused(
    tmp_path: Path, path: str, capsys: pytest.CaptureFixture[str]
) -> None:
    session = session_with_path(tmp_path, path)
    assert main(["session", "verify", str(session)]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "manifest.jsonl line 1: `path` is" in err and "session folder" in err


def test_resume_refuses_a_session_whose_snapshot_runs_a_program(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A foreign session's session.yaml names a program: --yes alone never runs it."""
    pytest.importorskip("drivers.sim")
    marker = tmp_path / "ran"
    profile = yaml.safe_load((ROOT / "tests/rig/sim-small.yaml").read_text())
    profile["plan"]["views"] = 1
    light = [sys.executable, "-m", "drivers.lights.rgbcw_emulator"]
    profile["devices"]["light"] = {
        "driver": "rgbcw-serial",
        "transport": {"type": "subprocess", "command": light},
    }
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(profile))
    out = tmp_path / "s"
    monkeypatch.chdir(ROOT)  # the child imports drivers from the checkout
    assert main(["capture", "--yes", "--profile", str(path), "--out", str(out)]) == 0
    info = yaml.safe_load((out / "session.yaml").read_text())
    hostile = [sys.executable, "-c", f"open({str(marker)!r}, 'w')"]
    info["profile"]["devices"]["light"]["transport"]["command"] = hostile
    (out / "session.yaml").write_text(yaml.safe_dump(info, sort_keys=False))
    capsys.readouterr()
    assert main(["capture", "--yes", "--resume", str(out)]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "session.yaml: devices.light runs" in err and "--trust-session-devices" in err
    assert not marker.exists()
    info["profile"]["devices"]["light"]["transport"]["command"] = light
    (out / "session.yaml").write_text(yaml.safe_dump(info, sort_keys=False))
    assert main(["capture", "--yes", "--resume", str(out), "--trust-session-devices"]) == 0


@pytest.mark.parametrize(("answer", "ok"), [("y", True), ("yes", True), ("", False), ("n", False)])
def test_the_person_is_asked_before_a_snapshot_program_runs(answer: str, ok: bool) -> None:
    profile = parse_profile(
        {
            "name": "p",
            "devices": {
                "camera": {"driver": "sim"},
                "light": {"driver": "dmx", "transport": {"kind": "subprocess", "command": "ola"}},
            },
            "illuminations": {"A": {"r": 1.0}},
            "plan": {"views": 2, "illuminations": "all"},
            "light_mount": {"type": "plate", "offset_m": [0.1, 0.0, 0.0]},
        },
        "p.yaml",
    )
    asked: list[str] = []

    def ask(text: str) -> str:
        asked.append(text)
        return answer

    def confirm() -> None:
        confirm_session_devices(Path("s"), profile, trusted=False, ask=ask, interactive=True)

    if ok:
        confirm()
    else:
        with pytest.raises(RigError, match="not confirmed, nothing was run"):
            confirm()
    assert len(asked) == 1 and "devices.light runs `ola`" in asked[0]
    with pytest.raises(RigError, match="--trust-session-devices"):  # no TTY: never asks
        confirm_session_devices(Path("s"), profile, trusted=False, ask=ask, interactive=False)
    confirm_session_devices(Path("s"), profile, trusted=True, ask=None, interactive=False)


@pytest.mark.parametrize(
    "transport",
    [
        {"type": "serial", "kind": "subprocess", "command": ["ola"]},  # `kind` wins when opened
        {"kind": "subprocess", "command": ["ola"]},
    ],
)
def test_the_trust_check_reads_the_transport_as_the_registry_opens_it(transport: dict) -> None:
    profile = parse_profile(
        {
            "name": "p",
            "devices": {
                "camera": {"driver": "sim"},
                "light": {"driver": "dmx", "transport": transport},
            },
            "illuminations": {"A": {"r": 1.0}},
            "plan": {"views": 2, "illuminations": "all"},
            "light_mount": {"type": "plate", "offset_m": [0.1, 0.0, 0.0]},
        },
        "p.yaml",
    )
    assert session_programs(profile) == ["devices.light runs `ola`"]
