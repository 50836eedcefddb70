"""`rig` in its own process, sent SIGINT or SIGTERM at a chosen instant: the checks every
signal test makes (exit 128 + N, stderr ending with the one stop line, no Python traceback and
no native stack dump) and the seeded instants (start-up included)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
SIGNALS = (signal.SIGINT, signal.SIGTERM)
STOP_LINE = "rig: stopped by"
NEVER = ("Traceback", "*** Aborted", "received by PID", "KeyboardInterrupt")
STARTUP_S = 0.5  # every third instant falls in the first half second


def _block_signals() -> None:
    signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)


def spawn(args: Sequence[str]) -> subprocess.Popen[bytes]:
    """``python -m rig.cli ARGS``, started with SIGINT and SIGTERM blocked: a signal sent while
    the interpreter itself starts, before any line of rig runs, waits for rig's handlers (they
    unblock both) instead of meeting Python's defaults."""
    return subprocess.Popen(
        [sys.executable, "-m", "rig.cli", *args],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env={**os.environ, "NO_COLOR": "1"},
        preexec_fn=_block_signals,
    )


@dataclass(frozen=True)
class Outcome:
    signum: int
    delay_s: float
    returncode: int
    stderr: str
    finished_first: bool  # the command had done its work before the signal reached it


def signal_at(args: Sequence[str], signum: int, delay_s: float, done_marker: str) -> Outcome:
    """Start ``rig ARGS`` and send ``signum`` ``delay_s`` after it started, unless it has
    exited by then; ``done_marker`` on stderr says the command had finished its work."""
    proc = spawn(args)
    time.sleep(delay_s)
    if proc.poll() is None:
        proc.send_signal(signum)
    _, err = proc.communicate(timeout=600)
    text = err.decode(errors="replace")
    finished = proc.returncode in (0, -signum) and done_marker in text
    return Outcome(signum, delay_s, proc.returncode, text, finished)


def check(outcome: Outcome) -> None:
    """A stopped run: 128 + N and the stop line last, once; a finished one: exit 0 (or the
    signal's default action in the interpreter's last milliseconds, after rig's last line)."""
    text = outcome.stderr
    assert not any(word in text for word in NEVER), text
    if outcome.finished_first:
        return
    code = 128 + outcome.signum
    name = signal.Signals(outcome.signum).name
    assert outcome.returncode == code, (outcome.delay_s, outcome.returncode, text)
    lines = [line for line in text.splitlines() if line.strip()]
    assert lines[-1].startswith(f"{STOP_LINE} {name} (exit {code})"), text
    assert sum(STOP_LINE in line for line in lines) == 1, text


def pick(rng: np.random.Generator, index: int, length_s: float) -> tuple[int, float]:
    """The ``index``-th (signal, delay): every third delay within the start-up, the others
    anywhere in a run of ``length_s``."""
    top = min(STARTUP_S, length_s) if index % 3 == 0 else length_s
    return int(rng.choice(SIGNALS)), float(rng.uniform(0.0, top))


def timed_run(args: Sequence[str]) -> float:
    """Wall seconds of one uninterrupted ``rig ARGS`` (which must succeed)."""
    start = time.perf_counter()
    proc = spawn(args)
    _, err = proc.communicate(timeout=900)
    assert proc.returncode == 0, err.decode(errors="replace")[-3000:]
    return time.perf_counter() - start
