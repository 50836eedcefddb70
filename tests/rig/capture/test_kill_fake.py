"""SIGKILL a capture (fake devices, own process) at random instants, including start-up and
mid-frame, then resume: nothing completed is lost, nothing is duplicated."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from core.manifest import read_manifest, verify_frames

SCRIPT = Path(__file__).parents[1] / "fakes.py"
FRAMES = 6 * 4


def start(session: Path, resume: bool) -> subprocess.Popen[bytes]:
    args = [sys.executable, str(SCRIPT), str(session)] + (["--resume"] if resume else [])
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[3])}
    return subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)


@pytest.mark.parametrize("seed", [11, 12])
def test_random_sigkills_then_resume(tmp_path: Path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    out = tmp_path / "s"
    proc = start(out, resume=False)
    for _ in range(3):
        time.sleep(float(rng.uniform(0.0, 1.2)))  # start-up, or anywhere in the frames
        if proc.poll() is not None:
            break
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        proc = start(out, resume=True)
    assert proc.wait(timeout=120) == 0, proc.stderr.read().decode() if proc.stderr else ""
    records = read_manifest(out)
    counts = Counter(r.frame for r in records)
    assert sorted(counts) == list(range(FRAMES)) and max(counts.values()) == 1
    assert verify_frames(out, records) == []
    assert {p.name for p in (out / "raw").iterdir() if p.is_file()} == {
        Path(r.path).name for r in records
    }
