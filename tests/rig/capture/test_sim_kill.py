"""`rig capture` in its own process on the simulated rig: SIGKILL at random instants and
Ctrl-C, then `--resume`: the manifest ends complete, every hash verifies, nothing duplicated."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from simrig import FRAMES, PROFILE, assert_complete, manifest_lines, rig_capture

from core.manifest import read_manifest, verify_frames
from core.session import Session
from rig.cli import main

pytest.importorskip("drivers.sim")


@pytest.mark.parametrize(
    "seed", [1, pytest.param(2, marks=pytest.mark.slow), pytest.param(3, marks=pytest.mark.slow)]
)
def test_sigkill_at_random_instants_then_resume(tmp_path: Path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    out = tmp_path / "s"
    proc = rig_capture("--profile", str(PROFILE), "--out", str(out))
    kills = 0
    while True:
        done = manifest_lines(out)
        target = done + int(rng.integers(1, max(2, FRAMES - done)))  # a random later frame
        deadline = time.monotonic() + 120
        while manifest_lines(out) < target and proc.poll() is None:
            assert time.monotonic() < deadline, "capture made no progress"
            time.sleep(0.01)
        until = time.monotonic() + float(rng.uniform(0.0, 0.15))  # anywhere inside the next frame
        while time.monotonic() < until and manifest_lines(out) <= target and proc.poll() is None:
            time.sleep(0.002)
        if proc.poll() is not None:
            assert proc.returncode == 0, proc.stderr.read().decode() if proc.stderr else ""
            break
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        kills += 1
        assert read_manifest(out) is not None  # a kill never leaves an unreadable manifest
        proc = rig_capture("--resume", str(out))
    assert kills >= 1
    assert_complete(out)
    runs = Session.open(out).info.runs
    # a resume killed after re-adopting a frame but before recording its run leaves no run
    assert 2 <= len(runs) <= kills + 1 and runs[-1]["status"] == "complete"


def test_ctrl_c_exits_130_with_the_resume_command(tmp_path: Path) -> None:
    out = tmp_path / "s"
    proc = rig_capture("--profile", str(PROFILE), "--out", str(out))
    deadline = time.monotonic() + 120
    while manifest_lines(out) < 3:
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.01)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    text = "".join(err.decode().split())  # the console may wrap the message anywhere
    assert "".join(f"rig capture --resume {out}".split()) in text
    records = read_manifest(out)
    assert 3 <= len(records) < FRAMES and verify_frames(out, records) == []
    assert Session.open(out).info.runs[-1]["status"] == "stopped"
    assert main(["capture", "--resume", str(out), "--yes"]) == 0
    assert_complete(out)
