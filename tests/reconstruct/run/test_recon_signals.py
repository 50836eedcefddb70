"""SIGINT and SIGTERM at seeded random instants of `rig reconstruct` on a tiny simulated
session, its start-up included: every stopped run exits 130 / 143 with one line and no
traceback or native dump, leaves the status `interrupted` (or none yet) and the session intact,
and the next run resumes, ending with the same result as an uninterrupted run."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from recon_tiny import make_session, reconstruct_args

from reconstruct.outputs import export
from reconstruct.run.status import read_status
from rig.cli import main
from tests.rig.signal_runs import STARTUP_S, check, pick, signal_at, timed_run

pytest.importorskip("drivers.sim")
DONE = "reflectance scale"  # a row of the summary printed after the run


def stop_reconstructions(
    session: Path, config: Path, seed: int, stops: int, length_s: float
) -> tuple[int, list[tuple[float, int, str]]]:
    """Stop `rig reconstruct` runs until ``stops`` were stopped, each resuming the last; after
    a run that finished before its signal the outputs are removed so the next one works
    again. Returns the runs, and the delay, exit code and last line of each that finished."""
    rng = np.random.default_rng(seed)
    recon = session / "recon"
    runs = stopped = 0
    finished: list[tuple[float, int, str]] = []
    while stopped < stops:
        signum, delay = pick(rng, runs, length_s)
        outcome = signal_at(reconstruct_args(session, config), signum, delay, DONE)
        check(outcome)
        runs += 1
        status = read_status(recon)
        # the run may finish before its signal, or take it while printing its summary, after
        # the status says complete (then 130/143 is right and the outputs are whole)
        if outcome.finished_first or (status is not None and status["status"] == "complete"):
            assert status is not None and status["status"] == "complete"
            finished.append((outcome.delay_s, outcome.returncode, outcome.stderr.strip()[-200:]))
            shutil.rmtree(recon)
            continue
        stopped += 1
        assert status is None or status["status"] == "interrupted", (outcome, status)
        assert main(["session", "verify", str(session)]) == 0
    return runs, finished


def test_signals_during_start_up_exit_130_or_143_and_leave_the_session_intact(
    tmp_path: Path,
) -> None:
    session, config = make_session(tmp_path)
    runs, finished = stop_reconstructions(session, config, seed=3, stops=4, length_s=STARTUP_S)
    assert runs == 4, finished  # no run gets to finish within its start-up


@pytest.mark.slow
def test_twenty_signals_at_random_instants_of_rig_reconstruct(tmp_path: Path) -> None:
    session, config = make_session(tmp_path)
    clean = tmp_path / "clean"
    shutil.copytree(session, clean)
    length = timed_run(reconstruct_args(clean, config))
    runs, _ = stop_reconstructions(session, config, seed=23, stops=20, length_s=length)
    print(f"reconstruct: {length:.1f} s uninterrupted; 20 of {runs} runs stopped by a signal")
    assert main(reconstruct_args(session, config)) == 0
    status = read_status(session / "recon")
    assert status is not None and status["status"] == "complete"
    result = export.read_reflectance_npz(session / "recon" / export.REFLECTANCE_FILE)
    reference = export.read_reflectance_npz(clean / "recon" / export.REFLECTANCE_FILE)
    for key in ("vertices", "faces", "reflectance", "alpha", "observed"):
        np.testing.assert_array_equal(result[key], reference[key], err_msg=key)
