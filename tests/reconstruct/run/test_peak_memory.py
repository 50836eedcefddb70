"""Peak resident memory per stage: the high-water mark is reset before a stage and read after
it, and a reconstruction reports each stage's peak in report.json and timings.json."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from types import SimpleNamespace
from typing import cast

import numpy as np
import psutil
import pytest
from recon_tiny import make_session, reconstruct_args

from reconstruct.optimise.problem import Frames
from reconstruct.optimise.settings import OptimiseInput, OptimiseSettings
from reconstruct.outputs import export
from reconstruct.run import pipeline
from reconstruct.stages.memory import (
    memory_within_reach_gb,
    peak_rss_mb,
    reset_peak_rss,
    solve_memory_gb,
)
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


def test_the_solve_estimate_counts_pairs_and_frames() -> None:
    assert solve_memory_gb(2_000_000, 0) == pytest.approx(solve_memory_gb(0, 0) + 1.0)
    assert solve_memory_gb(0, 3 * 10**9) == pytest.approx(solve_memory_gb(0, 0) + 3.0)
    # what this process holds counts as within reach: never less than its own resident memory
    assert memory_within_reach_gb() >= psutil.Process().memory_info().rss / 1e9


def test_a_solve_larger_than_the_memory_left_is_warned_of(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    visibility = np.ones((1000, 4), bool)
    visibility[:500, 3] = False  # view 3 sees half the vertices
    images, valid = np.zeros((8, 6, 8, 3), np.float16), np.ones((8, 6, 8), bool)
    frames = Frames(np.repeat(np.arange(4), 2), np.tile([0, 1], 4), images, valid)
    inp = cast(OptimiseInput, SimpleNamespace(vertices=np.zeros((1000, 3)),
                                              visibility=visibility, frames=frames))
    need = solve_memory_gb(7000, images.nbytes + valid.nbytes)  # 7000: (3 × 1000 + 500) × 2
    monkeypatch.setattr(pipeline, "memory_within_reach_gb", lambda: need - 0.01)
    with caplog.at_level(logging.WARNING, logger="reconstruct"):
        pipeline.warn_if_solve_exceeds_memory(inp, OptimiseSettings())
    assert "1000 vertices, 7000 vertex-frame pairs" in caplog.text
    assert "coarser --detail" in caplog.text
    caplog.clear()
    # more than the solve needs, less than it needs with a second copy of the frames
    frames_gb = (images.nbytes + valid.nbytes) / 1e9
    monkeypatch.setattr(pipeline, "memory_within_reach_gb", lambda: need + frames_gb / 2)
    with caplog.at_level(logging.WARNING, logger="reconstruct"):
        pipeline.warn_if_solve_exceeds_memory(inp, OptimiseSettings())
    assert not caplog.records
    # blurred first stages sample a blurred copy of the frames beside them
    with caplog.at_level(logging.WARNING, logger="reconstruct"):
        pipeline.warn_if_solve_exceeds_memory(inp, OptimiseSettings(coarse_blur_px=2.0))
    assert "1000 vertices, 7000 vertex-frame pairs" in caplog.text
