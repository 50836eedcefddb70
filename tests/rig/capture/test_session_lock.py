"""Two commands on one session at once: while `rig capture --out S` runs (in its own process,
on the simulated rig, slowed by the plan's settle time), `rig capture --resume S` and
`rig reconstruct S` are refused with one line naming it, and the session ends intact."""

from __future__ import annotations

import json
import re
import signal
import time
from pathlib import Path

import pytest
import yaml
from lockholder import hold, release_all
from simrig import PROFILE, assert_complete, manifest_lines, rig_capture

from core.lock import LOCK_FILE
from rig.cli import main

pytest.importorskip("drivers.sim")


def slow_profile(tmp_path: Path) -> Path:
    profile = yaml.safe_load(PROFILE.read_text())
    profile["plan"]["settle_s"] = 0.4  # each light switch: time for the other commands
    path = tmp_path / "slow.yaml"
    path.write_text(yaml.safe_dump(profile))
    return path


def refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    code = main(argv)
    text = " ".join("".join(capsys.readouterr()).split())
    assert code == 2, text
    assert text.count("error:") == 1 and "Traceback" not in text
    return text


def test_a_second_capture_and_a_reconstruction_are_refused_while_one_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "s"
    proc = rig_capture("--profile", str(slow_profile(tmp_path)), "--out", str(out))
    try:
        deadline = time.monotonic() + 120
        while manifest_lines(out) < 1:
            assert proc.poll() is None and time.monotonic() < deadline, "capture did not start"
            time.sleep(0.01)
        holder = rf"in use by `rig capture` \(PID {proc.pid} on .+, since \S+Z\)"
        text = refused(["capture", "--resume", str(out), "--yes"], capsys)
        assert re.search(rf"{re.escape(str(out))} is {holder} — wait for it to finish", text)
        assert re.search(holder, refused(["reconstruct", str(out)], capsys))
        assert proc.poll() is None  # refused because it was still running
        assert not (out / "recon").exists()  # the refused reconstruction wrote nothing
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err.decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert_complete(out)  # every frame once, every hash verified, no duplicate line
    assert main(["session", "verify", str(out)]) == 0
    assert not (out / LOCK_FILE).exists()


def test_a_capture_killed_while_holding_the_lock_does_not_block_its_resume(
    tmp_path: Path,
) -> None:
    out = tmp_path / "s"
    proc = rig_capture("--profile", str(PROFILE), "--out", str(out))
    deadline = time.monotonic() + 120
    while manifest_lines(out) < 2:
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert json.loads((out / LOCK_FILE).read_text())["pid"] == proc.pid  # left by the kill
    assert main(["capture", "--resume", str(out), "--yes"]) == 0
    assert_complete(out)
    assert not (out / LOCK_FILE).exists()


def test_a_held_session_is_refused_and_left_unchanged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "s"
    profile = yaml.safe_load(PROFILE.read_text())
    profile["plan"]["views"] = 1
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(profile))
    assert main(["capture", "--yes", "--profile", str(tmp_path / "p.yaml"), "--out", str(out)]) == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    hold(out, "rig reconstruct")
    try:
        text = refused(["capture", "--resume", str(out), "--yes"], capsys)
        assert "is in use by `rig reconstruct`" in text
        new = tmp_path / "fresh"
        hold(new.parent, "rig batch")  # a lock on another folder is no hindrance
        assert main(["capture", "--yes", "--profile", str(tmp_path / "p.yaml"), "--out",
                     str(new)]) == 0
    finally:
        release_all()
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
