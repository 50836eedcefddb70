"""bench.ambient_uncertainty runs end to end at its ``--quick`` size and reports sane numbers."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_ambient_uncertainty_bench(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "bench.ambient_uncertainty", "--quick", "--out", str(tmp_path)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    results = json.loads((tmp_path / "results.json").read_text())["results"]
    assert len(results) == 3
    for run in results.values():
        assert 0 < run["rmse"] < 1
        c = run["calibration"]
        assert 0 <= c["inside_2sigma_all_bands"] <= c["inside_2sigma_per_band"] <= 1
        assert -1 <= run["spearman_std_vs_error"] <= 1
    assert (tmp_path / "calibration.png").stat().st_size > 0
