"""`rig check-chart` on a Mitsuba-rendered session of a flat ColorChecker (true reflectances,
measured lamps and camera): the chart is found in every view and the ΔE00 it reports per patch
is what the session's calibration gives when the shading is known."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from bench.chart_check import LIGHTS, score
from bench.chart_session import build_chart_session
from rig.cli import main

pytestmark = pytest.mark.slow  # a Mitsuba render of two views: about 25 s


@pytest.fixture(scope="module")
def checked(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    session = build_chart_session(tmp_path_factory.mktemp("chart"), shared_data)
    assert main(["check-chart", str(session)]) == 0
    out = session / "recon" / "chart_check"
    return session, json.loads((out / "chart_check.json").read_text())


def test_the_chart_is_found_in_every_view_and_the_files_are_written(checked) -> None:
    session, result = checked
    assert [v["view"] for v in result["views"]] == [0, 1]  # view 1 sees the chart upside down
    out = session / "recon" / "chart_check"
    assert (out / "chart_check.png").stat().st_size > 10_000
    lines = (out / "chart_check.csv").read_text().splitlines()
    assert lines[0] == "patch,name,delta_e00_D65,delta_e00_A,rmse" and len(lines) == 25


def test_delta_e_per_patch_is_the_one_known_shading_gives(checked) -> None:
    session, result = checked
    scored = score(session, result)
    for light in LIGHTS:
        reported, known, floor = (scored[light][k] for k in ("reported", "known_shading", "floor"))
        assert np.max(np.abs(reported - known)) < 0.3, light
        # against the noise-free floor the scene's own noise adds to it
        assert np.mean(np.abs(reported - floor)) < 0.3, light
        assert np.max(np.abs(reported - floor)) < 0.6, light
