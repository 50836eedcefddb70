"""Tiny simulated sessions for the batch and quiet-output tests (seconds to reconstruct with
``fast.yaml``)."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

from rich.console import Console

from rig.capture import run_capture

HERE = Path(__file__).parent
PROFILE = HERE / "sim-batch.yaml"
FAST = HERE / "fast.yaml"


def capture(out: Path) -> Path:
    """A 4-view session from the simulated rig (real Bayer DNGs, calibration snapshot)."""
    run_capture(PROFILE, out, yes=True, seed=0, console=Console(file=io.StringIO()))
    return out


def copies(template: Path, root: Path, names: list[str]) -> list[Path]:
    """Independent copies of a captured session (cheaper than capturing each)."""
    out = []
    for name in names:
        shutil.copytree(template, root / name)
        out.append(root / name)
    return out
