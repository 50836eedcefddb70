"""A tiny simulated session for the reconstruction safety tests: 8 views × 2 illuminations of
128×96 px with known poses, and a config (no subdivision, short solves) that reconstructs it
in seconds from the sim's own coarse mesh as the initial mesh."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from rig.cli import main

HERE = Path(__file__).parent
PROFILE = HERE / "sim-tiny.yaml"
CONFIG = """\
subdivide: {max_steps: 1, max_faces: 4000}
optimise: {outer_iterations: 3, light_iterations: 6, joint_iterations: 4}
"""


def make_session(root: Path) -> tuple[Path, Path]:
    """Capture the tiny session into ``root/s``; returns it and its reconstruct config."""
    session = root / "s"
    assert main(["capture", "--profile", str(PROFILE), "--out", str(session), "--yes"]) == 0
    config = root / "recon.yaml"
    config.write_text(CONFIG)
    return session, config


def reconstruct_args(session: Path, config: Path) -> list[str]:
    return [
        "reconstruct",
        str(session),
        "--config",
        str(config),
        "--initial-mesh",
        str(session / "ground_truth" / "mesh.ply"),
    ]


def spawn(args: list[str]) -> subprocess.Popen[bytes]:
    """``rig ARGS`` in its own process (so it can be killed), output discarded."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "NO_COLOR": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", "rig.cli", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=env,
    )
