"""`rig check-chart` on a Mitsuba-rendered session of a flat ColorChecker (true reflectances,
measured lamps and camera): the chart is found in every view and the ΔE00 it reports per patch
is what the session's calibration gives when the shading is known."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mitsuba")
from bench.chart_session import build_chart_session
from calibration.basis import default_basis
from calibration.colour_difference import delta_e00, illuminant
from calibration.defaults import colorchecker_reflectances
from calibration.estimation import estimate_reflectance
from core.session import Session
from reconstruct.run.pipeline import session_responses
from rig.cli import main

pytestmark = pytest.mark.slow  # a Mitsuba render of two views: about 25 s


@pytest.fixture(scope="module")
def checked(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    session = build_chart_session(tmp_path_factory.mktemp("chart"), shared_data)
    assert main(["check-chart", str(session)]) == 0
    out = session / "recon" / "chart_check"
    return session, json.loads((out / "chart_check.json").read_text())


def _delta_e(estimate: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    return {n: delta_e00(estimate, truth, illuminant(n)) for n in ("D65", "A")}


def test_the_chart_is_found_in_every_view_and_the_files_are_written(checked) -> None:
    session, result = checked
    assert [v["view"] for v in result["views"]] == [0, 1]  # view 1 sees the chart upside down
    out = session / "recon" / "chart_check"
    assert (out / "chart_check.png").stat().st_size > 10_000
    lines = (out / "chart_check.csv").read_text().splitlines()
    assert lines[0] == "patch,name,delta_e00_D65,delta_e00_A,rmse" and len(lines) == 25


def test_delta_e_per_patch_is_the_one_known_shading_gives(checked) -> None:
    session, result = checked
    responses = session_responses(Session.open(session))
    basis = default_basis()
    truth = colorchecker_reflectances()[1]
    predicted = np.einsum("kcl,pl->pkc", responses, truth)
    names = result["illuminations"]
    oracle = []  # each view's patches divided by their true shading
    for view in result["views"]:
        y = np.stack([np.array(view["rgb"][n]) for n in names], axis=1)
        shading = np.median((y / predicted).reshape(24, -1), axis=1)
        oracle.append(estimate_reflectance(y / shading[:, None, None], responses, basis)[1])
    known = _delta_e(np.median(oracle, axis=0), truth)
    floor = _delta_e(estimate_reflectance(predicted, responses, basis)[1], truth)
    for light in ("D65", "A"):
        reported = np.array([row[f"delta_e00_{light}"] for row in result["patches"]])
        assert np.max(np.abs(reported - known[light])) < 0.3, light
        # against the noise-free floor the scene's own noise adds to it
        assert np.mean(np.abs(reported - floor[light])) < 0.3, light
        assert np.max(np.abs(reported - floor[light])) < 0.6, light
