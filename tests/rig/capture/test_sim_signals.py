"""SIGINT and SIGTERM at seeded random instants of `rig capture` on the simulated rig, its
start-up included: every stopped run exits 130 / 143 with one line and no traceback or native
dump, the next run resumes the session, and each session ends complete and verified."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from signal_runs import STARTUP_S, check, pick, signal_at, timed_run
from simrig import PROFILE, assert_complete

from rig.cli import main

pytest.importorskip("drivers.sim")
DONE = "capture complete"


def capture_args(session: Path) -> list[str]:
    """A new session, or the next run of a stopped one (`--profile` starts afresh one
    stopped before its session.yaml existed)."""
    if not session.exists():
        return ["capture", "--yes", "--profile", str(PROFILE), "--out", str(session)]
    return ["capture", "--yes", "--resume", str(session), "--profile", str(PROFILE)]


def finish(session: Path) -> None:
    assert main(capture_args(session)) == 0
    assert_complete(session)
    assert main(["session", "verify", str(session)]) == 0


def stop_captures(tmp_path: Path, seed: int, stops: int, length_s: float) -> int:
    """Stop captures until ``stops`` runs were stopped, each run resuming the last; a session
    a run finished before its signal is verified and replaced by a new one. Returns the runs."""
    rng = np.random.default_rng(seed)
    session = tmp_path / "s0"
    runs = stopped = 0
    while stopped < stops:
        signum, delay = pick(rng, runs, length_s)
        outcome = signal_at(capture_args(session), signum, delay, DONE)
        check(outcome)
        runs += 1
        if outcome.finished_first:
            finish(session)
            session = tmp_path / f"s{runs}"
        else:
            stopped += 1
    finish(session)
    return runs


def test_signals_during_start_up_exit_130_or_143_and_the_capture_resumes(
    tmp_path: Path,
) -> None:
    assert stop_captures(tmp_path, seed=5, stops=4, length_s=STARTUP_S) == 4


@pytest.mark.slow
def test_twenty_signals_at_random_instants_of_rig_capture(tmp_path: Path) -> None:
    length = timed_run(capture_args(tmp_path / "reference"))
    runs = stop_captures(tmp_path, seed=11, stops=20, length_s=length)
    print(f"capture: {length:.1f} s uninterrupted; 20 of {runs} runs stopped by a signal")
