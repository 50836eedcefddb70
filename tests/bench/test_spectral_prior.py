"""bench.spectral_prior: the table of the estimator's floor under each regulariser."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.external import SCENES
from bench.external_scene import DATA
from bench.spectral_prior import main, munsell


def test_munsell_chips_are_reflectances_on_the_grid() -> None:
    if not (DATA / "reflectance").is_dir():
        pytest.skip(f"no shared data at {DATA}")
    chips = munsell(DATA)
    assert chips.shape == (1269, 31)
    assert 0.0 <= chips.min() and chips.max() <= 1.0


def test_the_table_covers_both_regularisers_and_every_pair(tmp_path: Path) -> None:
    if not (DATA / "reflectance").is_dir():
        pytest.skip(f"no shared data at {DATA}")
    assert main(["--noise", "0.01", "--seeds", "1", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "spectral_prior.json").read_text())["rows"]
    assert {r["regulariser"] for r in rows} == {"smoothness", "training"}
    assert {r["scene"] for r in rows} == set(SCENES)  # every external scene's camera and lamps
    assert all(0 < r["de_d65"] < 10 and 0 < r["rmse"] < 0.2 for r in rows)
    assert (tmp_path / "spectral_prior.md").is_file()
