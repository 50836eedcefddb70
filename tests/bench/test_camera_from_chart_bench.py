"""`bench.camera_from_chart` runs end to end at its ``--quick`` size and its numbers make sense:
the fit is closer to the held-out cameras than the prior's mean, and no worse downstream."""

from __future__ import annotations

from pathlib import Path

from test_bench_smoke import run_bench


def test_camera_from_chart_bench(tmp_path: Path, shared_data: Path) -> None:
    data = run_bench("bench.camera_from_chart", tmp_path, "--data", str(shared_data))
    rows = {(r[0], r[1], r[2]): r for r in data["tables"][0]["rows"]}
    prior_rmse = float(rows[("prior mean (no photo)", "-", "-")][3].split(" / ")[0])
    fit = rows[("fit, 4 components (default)", "sensor", "2")]
    assert float(fit[3].split(" / ")[0]) < 0.8 * prior_rmse
    floor = float(rows[("true sensitivity (floor)", "-", "-")][5].split(" / ")[0])
    prior_de = float(rows[("prior mean (no photo)", "-", "-")][5].split(" / ")[0])
    assert floor <= float(fit[5].split(" / ")[0]) < prior_de
    assert len(data["tables"][1]["rows"]) == 3
