"""Peak resident memory per stage: the high-water mark is reset before a stage and read after
it, and a reconstruction reports each stage's peak in report.json and timings.json."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from recon_tiny import make_session, reconstruct_args

from reconstruct.outputs import export
from reconstruct.stages.memory import peak_rss_mb, reset_peak_rss
from rig.cli import main


def test_a_reset_forgets_an_earlier_peak() -> None:
    if not reset_peak_rss():
        pytest.skip("this kernel does not reset the high-water mark")
    base = peak_rss_mb()
    block = np.ones(40_000_000)  # 320 MB, touched
    grown = peak_rss_mb()
    del block
    assert grown - base > 250
    reset_peak_rss()
    assert peak_rss_mb() < grown - 250


@pytest.mark.slow
def test_the_report_has_each_stages_peak(tmp_path: Path) -> None:
    session, config = make_session(tmp_path)
    assert main(reconstruct_args(session, config)) == 0
    recon = session / "recon"
    peaks = json.loads((recon / export.REPORT_FILE).read_text())["peak_rss_mb"]
    assert {"decode", "visibility", "optimise", "export"} <= set(peaks)
    assert all(peaks[k] > 50 for k in ("decode", "optimise", "export"))
    timings = json.loads((recon / "timings.json").read_text())
    assert timings["optimise"]["peak_rss_mb"] == peaks["optimise"]
