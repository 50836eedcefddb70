"""Another process holding a folder's lock (core.lock) as a running command would, until
released: for the tests of refused concurrent commands."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HOLDER = """
import sys
from core.lock import locked
with locked(sys.argv[1], sys.argv[2]):
    print("held", flush=True)
    sys.stdin.read()  # until the test closes the pipe (or ends)
"""
ROOT = Path(__file__).parents[2]
_holders: list[subprocess.Popen[str]] = []


def hold(folder: Path, command: str = "rig capture") -> subprocess.Popen[str]:
    """Lock ``folder`` from another process; returns once it is held."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(folder), command],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env={"PYTHONPATH": str(ROOT)},
    )
    assert proc.stdout is not None and proc.stdout.readline() == "held\n"
    _holders.append(proc)
    return proc


def release_all() -> None:
    """End every holder this process started."""
    while _holders:
        proc = _holders.pop()
        assert proc.stdin is not None
        proc.stdin.close()
        proc.wait(timeout=60)
        assert proc.stdout is not None
        proc.stdout.close()
