"""Shared helpers for the simulated-rig tests: the tiny profile, running `rig capture` in its
own process, and the completeness check every kill/resume test ends with."""

from __future__ import annotations

import subprocess
import sys
from collections import Counter
from pathlib import Path

import yaml

from core.manifest import read_manifest, verify_frames

PROFILE = Path(__file__).with_name("sim-small.yaml")
FRAMES = 4 * 4


def rig_capture(*args: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "rig.cli", "capture", "--yes", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        cwd=Path(__file__).parents[2],
    )


def manifest_lines(session: Path) -> int:
    path = session / "manifest.jsonl"
    return path.read_bytes().count(b"\n") if path.is_file() else 0


def assert_complete(session: Path) -> None:
    records = read_manifest(session)
    counts = Counter(r.frame for r in records)
    assert sorted(counts) == list(range(FRAMES)), "manifest incomplete"
    assert max(counts.values()) == 1, "duplicated frames"
    assert verify_frames(session, records) == []
    owned = {Path(r.path).name for r in records}
    assert {p.name for p in (session / "raw").iterdir() if p.is_file()} == owned


def capture_small_session(out: Path, views: int = 2) -> Path:
    """A complete sim session of ``views`` views at ``out`` (the small profile, in-process)."""
    from rig.capture import run_capture

    profile = yaml.safe_load(PROFILE.read_text())
    profile["plan"]["views"] = views
    path = out.parent / "p.yaml"
    path.write_text(yaml.safe_dump(profile))
    run_capture(path, out, yes=True)
    return out
