"""The demo's capture log: every view sees enough of the board for a pose (no warning to
ignore), and the coverage bar fills without gaps."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
import yaml
from rich.console import Console

from rig.capture import run_capture
from rig.demo_profile import demo_profile


@pytest.mark.slow
def test_the_demo_capture_warns_of_nothing_and_covers_each_ring(tmp_path: Path) -> None:
    profile = tmp_path / "demo-profile.yaml"
    profile.write_text(yaml.safe_dump(demo_profile(20), sort_keys=False))
    log = io.StringIO()
    run_capture(profile, tmp_path / "session", yes=True, seed=0,
                console=Console(file=log, width=300))
    text = log.getvalue()
    assert "board:" not in text and "exposure:" not in text, text
    bars = [line.split("0°[", 1)[1].split("]", 1)[0]
            for line in text.splitlines() if "coverage so far" in line]
    assert len(bars) == 20
    assert bars[9] == "█" * 9 + " " and bars[19] == "█" * 9 + " "  # last view of each ring
