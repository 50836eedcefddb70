"""20 SIGKILLs of `rig capture` on the simulated rig at seeded random instants, each followed
by `--resume`: no recorded frame is ever lost or changed, the session ends complete, and every
frame is byte-identical to an uninterrupted capture of the same scene (outputs never mixed).

The capture runs in a forked child (the same code path as `rig capture`, minus the seconds of
imports a fresh interpreter would spend) so 20 kills stay affordable."""

from __future__ import annotations

import multiprocessing
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from simrig import PROFILE

from core.manifest import read_manifest, verify_frames
from rig.capture.resume import QUARANTINE_DIR, REASONS_FILE
from rig.cli import main

pytest.importorskip("drivers.sim")

KILLS = 20
VIEWS = 30  # 120 frames: room for 20 kills of at most MAX_FRAMES_PER_RUN + 1 frames each
MAX_FRAMES_PER_RUN = 3


def capture_child(args: list[str]) -> None:
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    os._exit(main(["capture", "--yes", *args]))


def lines(session: Path) -> int:
    path = session / "manifest.jsonl"
    return path.read_bytes().count(b"\n") if path.is_file() else 0


def wait_at_most(session: Path, frames: int, seconds: float, proc: multiprocessing.Process) -> None:
    """Sleep `seconds`, or less once the manifest holds `frames` lines: on a fast machine the sim
    captures dozens of frames in the time window, and the capture must not finish before the
    last kill."""
    until = time.monotonic() + seconds
    while time.monotonic() < until and lines(session) < frames and proc.is_alive():
        time.sleep(0.002)


@pytest.mark.slow
def test_twenty_sigkills_lose_nothing_and_never_mix_frames(tmp_path: Path) -> None:
    profile = yaml.safe_load(PROFILE.read_text())
    profile["plan"]["views"] = VIEWS
    path = tmp_path / "sim-kill.yaml"
    path.write_text(yaml.safe_dump(profile))
    reference = tmp_path / "reference"
    assert main(["capture", "--yes", "--profile", str(path), "--out", str(reference)]) == 0
    expected = {r.frame: r.sha256 for r in read_manifest(reference)}

    context = multiprocessing.get_context("fork")
    rng = np.random.default_rng(20)
    out = tmp_path / "s"
    args = ["--profile", str(path), "--out", str(out)]
    recorded: dict[int, str] = {}
    kills = 0
    while kills < KILLS:
        proc = context.Process(target=capture_child, args=(args,))
        before = lines(out)
        proc.start()
        deadline = time.monotonic() + 120
        if rng.random() < 0.6:  # after the next frame lands, at a random instant of the one after
            while lines(out) <= before and proc.is_alive():
                assert time.monotonic() < deadline, "capture made no progress"
                time.sleep(0.005)
            wait_at_most(out, before + 1 + MAX_FRAMES_PER_RUN, float(rng.uniform(0.0, 0.1)), proc)
        else:  # anywhere in the start-up: opening devices, the resume checks, the first frame
            wait_at_most(out, before + MAX_FRAMES_PER_RUN, float(rng.uniform(0.0, 0.6)), proc)
        assert proc.is_alive(), f"capture ended (exit {proc.exitcode}) before kill {kills + 1}"
        os.kill(proc.pid, signal.SIGKILL)
        proc.join()
        kills += 1
        records = read_manifest(out)  # a kill never leaves an unreadable manifest
        frames = {r.frame: r.sha256 for r in records}
        assert set(recorded) <= set(frames), "a recorded frame was lost"
        for frame, digest in frames.items():
            assert recorded.setdefault(frame, digest) == digest == expected[frame]
        args = ["--profile", str(path), "--resume", str(out)]  # also before session.yaml
    proc = context.Process(target=capture_child, args=(args,))
    proc.start()
    proc.join(timeout=300)
    assert proc.exitcode == 0
    records = read_manifest(out)
    assert sorted(r.frame for r in records) == sorted(expected)
    assert {r.frame: r.sha256 for r in records} == expected
    assert verify_frames(out, records) == []
    owned = {Path(r.path).name for r in records}
    assert {p.name for p in (out / "raw").iterdir() if p.is_file()} == owned
    reasons = out / QUARANTINE_DIR / REASONS_FILE
    if reasons.is_file():  # only downloads cut by a kill may be set aside, never a frame
        assert all("unfinished download" in line for line in reasons.read_text().splitlines())
