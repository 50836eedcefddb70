"""Start-up time of `rig` commands that should answer at once: wall and CPU time (best of N
fresh interpreters) and the modules that cost most to import (``python -X importtime``).

    python -m bench.startup                  # this checkout
    python -m bench.startup --tree /work/main  # another checkout, for a before/after table
    python -m bench.startup --quick          # 2 runs per command
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import yaml

from bench._common import DEFAULT_OUT, REPO, ResultTable, machine_info, make_console, report

# Modules no light command should load (the test tests/rig/test_startup.py checks the parser).
HEAVY = ("pycolmap", "numba", "cv2", "colour", "matplotlib", "scipy", "trimesh", "rawpy", "numpy")
TOP_IMPORTS = 4

# The smallest session `rig session info` can read: 2 views x 1 illumination of 64x48 px.
TINY_PROFILE: dict[str, Any] = {
    "name": "startup-bench",
    "devices": {"light": {"driver": "sim"}, "camera": {"driver": "sim"}},
    "light_mount": {"type": "plate", "offset_m": [0.1, 0.0, 0.0]},
    "illuminations": {"LED2": {"w": 1.0}},
    "plan": {"views": 2, "illuminations": "all"},
    "calibration": {"store": "default", "camera": "Canon EOS 5D Mark II"},
    "poses": "known",
    "sim": {"subdivisions": 2, "camera": {"width": 64, "height": 48, "supersample": 1}},
}


def cases(session: Path) -> dict[str, list[str]]:
    return {
        "rig --help": ["--help"],
        "rig capture --help": ["capture", "--help"],
        "rig session info S": ["session", "info", str(session)],
        "rig capture --bogus (argument error)": ["capture", "--bogus"],
    }


def rig(tree: Path, args: list[str], *flags: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run(
        [sys.executable, *flags, "-m", "rig.cli", *args],
        cwd=tree,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )


def timed(tree: Path, args: list[str]) -> tuple[float, float, int]:
    """Wall and CPU seconds of one run, and its exit status."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = rig(tree, args)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, proc.returncode


def import_profile(tree: Path, args: list[str]) -> tuple[list[tuple[str, float]], list[str]]:
    """The costliest imports made directly by the program (cumulative ms) and the heavy
    packages among all of them."""
    err = rig(tree, args, "-X", "importtime").stderr
    top: list[tuple[str, float]] = []
    loaded: set[str] = set()
    for line in err.splitlines():
        if not line.startswith("import time:") or "|" not in line:
            continue
        _, cumulative, name = line.split("|", 2)
        if not cumulative.strip().isdigit():
            continue  # the header line
        module = name.strip()
        loaded.add(module.split(".")[0])
        if not name[1:].startswith(" "):  # not nested: imported by the program itself
            top.append((module, int(cumulative) / 1000))
    top.sort(key=lambda item: -item[1])
    return top[:TOP_IMPORTS], [m for m in HEAVY if m in loaded]


def tiny_session(tree: Path, work: Path) -> Path:
    """Capture the tiny sim session once (its time is not measured)."""
    profile = work / "startup-bench.yaml"
    profile.write_text(yaml.safe_dump(TINY_PROFILE))
    session = work / "session"
    proc = rig(tree, ["capture", "--yes", "--profile", str(profile), "--out", str(session)])
    if proc.returncode != 0:
        raise SystemExit(f"the tiny sim capture failed:\n{proc.stderr[-3000:]}")
    return session


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=REPO, help="checkout to measure")
    parser.add_argument("--runs", type=int, default=5, help="fresh interpreters per command")
    parser.add_argument("--quick", action="store_true", help="2 runs per command")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    runs = 2 if args.quick else args.runs
    tree = args.tree.resolve()
    console = make_console()
    info = machine_info()
    work = args.out / "startup_work"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    try:
        session = tiny_session(tree, work)
        table = ResultTable(
            f"rig start-up, {tree} (best of {runs} fresh interpreters)",
            ["command", "wall s", "CPU s", "exit", "heavy modules loaded", "top imports (ms)"],
        )
        measured: dict[str, Any] = {}
        for label, command in cases(session).items():
            samples = [timed(tree, command) for _ in range(runs)]
            wall = min(s[0] for s in samples)
            cpu = min(s[1] for s in samples)
            top, heavy = import_profile(tree, command)
            table.add(
                label,
                round(wall, 3),
                round(cpu, 3),
                samples[0][2],
                ", ".join(heavy) or "none",
                ", ".join(f"{name} {ms:.0f}" for name, ms in top),
            )
            measured[label] = {"wall_s": wall, "cpu_s": cpu, "heavy": heavy, "top_imports": top}
    finally:
        shutil.rmtree(work, ignore_errors=True)
    report(
        "startup",
        args.out,
        [table],
        {"tree": str(tree), "runs": runs, "commands": measured},
        info,
        console,
        notes=["wall: the whole process, interpreter start included; CPU: user + system"],
    )


if __name__ == "__main__":
    main()
