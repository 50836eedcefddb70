"""Each benchmark runs end to end at its ``--quick`` size through its command line and writes
its tables; the numbers are checked for sense (never for speed)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[2]


def run_bench(module: str, out: Path, *extra: str) -> dict[str, Any]:
    proc = subprocess.run(
        [sys.executable, "-m", module, "--quick", "--out", str(out), *extra],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    name = module.rsplit(".", 1)[1]
    data: dict[str, Any] = json.loads((out / f"{name}.json").read_text())
    markdown = (out / f"{name}.md").read_text()
    assert data["machine"]["cpu_count"] >= 1 and data["machine"]["ram_gb"] > 0
    assert "Machine:" in markdown and "|---|" in markdown
    assert all(t["rows"] for t in data["tables"])
    return data


@pytest.mark.slow
def test_capture_bench(tmp_path: Path) -> None:
    data = run_bench("bench.capture", tmp_path)
    overhead = data["in_process"]["overhead_ms"]
    assert data["in_process"]["frames"] == 8 and len(overhead) == 7
    assert all(ms > 0 for ms in overhead)
    assert all(ms > 0 for ms in data["components_ms"].values())
    worker, cli = data["resume"]
    assert worker["complete_and_verified"] is True
    assert worker["resume_to_next_frame_s"] > 0 and cli["resume_to_next_frame_s"] > 0
    assert 1 <= worker["frames_at_kill"] < 8
    assert not (tmp_path / "capture_work").exists()


@pytest.mark.slow
def test_startup_bench(tmp_path: Path) -> None:
    data = run_bench("bench.startup", tmp_path)
    commands = data["commands"]
    assert len(commands) == 4 and all(c["wall_s"] > 0 for c in commands.values())
    assert all(c["heavy"] == [] for c in commands.values())
    assert not (tmp_path / "startup_work").exists()


@pytest.mark.slow
def test_solver_bench(tmp_path: Path) -> None:
    data = run_bench("bench.solver", tmp_path)
    (run,) = data["runs"]
    opt, cmp = run["optimise"], run["compare"]
    assert run["vertices"] == 800 and opt["vertices"] == 800
    assert opt["iterations"] > 0 and math.isfinite(opt["final_cost"])
    assert opt["peak_rss_mb"] > 0
    ours = cmp["ours"]
    assert ours["final_cost"] < ours["start_cost"]
    if cmp["scipy"] is not None:  # killed when one scipy iteration outlasts the budget
        assert cmp["scipy"]["start_cost"] == pytest.approx(ours["start_cost"])
        assert cmp["scipy"]["jacobian_nnz"] > 0


@pytest.mark.slow
def test_paper_sim_bench(tmp_path: Path) -> None:
    data = run_bench("bench.paper_sim", tmp_path)
    blob = data["runs"]["blob"]
    for mode in ("joint", "baseline", "oracle"):
        r = blob[mode]
        assert 0 <= r["rmse_median"] and math.isfinite(r["rmse_mean"])
        assert r["observed_vertices"] > 0
        assert (tmp_path / f"paper_sim_blob_{mode}_spectral_error_map.png").is_file()
        d65 = next(c for c in r["colour"] if c["illuminant"] == "D65")
        assert d65["per_vertex"]["mean"] > 0 and len(d65["patches"]) > 0
    # the information floor: what the illuminations and camera allow, below every method
    floor = blob["floor"]
    assert 0 < floor["rmse_mean"] < blob["oracle"]["rmse_mean"]
    assert [c["illuminant"] for c in floor["colour"]] == ["D65", "A"]
    assert len(floor["colour"][0]["patches"]) == 24
    assert "ΔE00 D65 patch mean / max" in data["tables"][0]["columns"]
    assert blob["joint"]["light_position_error_m"] is not None
    # the oracle knows shape, light and shadows: its typical vertex beats the 2-D baseline's
    assert blob["oracle"]["rmse_median"] < blob["baseline"]["rmse_median"]
    assert blob["oracle"]["accuracy_m"] < 1e-9 < blob["baseline"]["accuracy_m"]
    assert (tmp_path / "paper_sim_blob_baseline_accuracy_error_map.png").is_file()


@pytest.mark.slow
def test_real_size_bench(tmp_path: Path) -> None:
    data = run_bench("bench.real_size", tmp_path)
    (run,) = data["runs"]
    assert run["report"]["vertices"] > 0 and run["report"]["observations"] > 0
    assert run["wall_s"] > 0 and run["cpu_s"] > 0 and run["peak_rss_mb"] > 0
    assert {"decode", "poses", "initial_mesh", "optimise", "export"} <= set(run["stages"])
    # the printed peak is never below a stage's own (per-stage resets hide those from ru_maxrss)
    table = data["tables"][0]
    printed_gb = float(table["rows"][0][table["columns"].index("peak RSS")].split()[0])
    stage_gb = max(e.get("peak_rss_mb") or 0.0 for e in run["stages"].values()) / 1e3
    assert printed_gb >= round(stage_gb, 2)
    assert 0 < run["score"]["accuracy_mm"] < 20 and 0 < run["score"]["rmse"] < 0.5
    assert (tmp_path / "runs" / "current" / "session" / "recon" / "mesh.ply").is_file()
    # the levels each stage used (320×240 frames: all at full size, PatchMatch at half)
    stages = data["tables"][1]
    levels = stages["rows"][0][stages["columns"].index("levels")]
    assert levels.startswith("decode 0 (320×240), patchmatch 1 (160×120), optimise 0 (320×240)")
