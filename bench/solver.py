"""Joint-optimisation benchmark: the paper's optimisation steps (light stage, then joint stages
with shadow rebuilds) on synthetic scenes of 25k–200k vertices × 40 views × 2 illuminations,
and — on the same cost, from the same start — one joint solve by our Levenberg–Marquardt
(matrix-free, preconditioned CG) against ``scipy.optimize.least_squares`` (trf, lsmr on the
sparse Jacobian), stopped when it reaches our final cost.

Every measured case runs in a fresh interpreter (its own peak RSS); scenes are rendered once and
cached under ``OUT/solver_cache``.

    python -m bench.solver                          # 25k, 50k, 100k, 200k; scipy at 25k
    python -m bench.solver --quick                  # smoke size
    python -m bench.solver --sizes 100000 --profile # pyinstrument profile of one size
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from bench._common import (
    DEFAULT_OUT,
    ResultTable,
    emit_worker_result,
    machine_info,
    make_console,
    report,
    run_worker,
)

TARGET_S = 300.0
TARGET_GB = 4.0
TARGET_RATIO = 10.0
PERTURB_M = 0.0005  # RMS of the smooth normal displacement of the start shape
LIGHT_ERROR_M = (0.01, -0.01, 0.005)  # start of the light offset in the solver comparison
EQUAL_COST = 1e-3  # scipy has "reached our cost" within this share


def _start(scene_path: Path, seed: int) -> tuple[Any, Any]:
    from bench._scene import load_scene
    from reconstruct.optimise.synthetic import perturb

    scene = load_scene(scene_path)
    x0 = perturb(scene, PERTURB_M, seed=seed + 1)
    return scene, scene.input(x0, images=True)


def worker_optimise(
    scene_path: Path, seed: int, profile_to: Path | None, settings: dict[str, Any]
) -> dict[str, Any]:
    """The full paper steps from the perturbed shape and a zero light offset."""
    from reconstruct.optimise.settings import OptimiseSettings
    from reconstruct.optimise.steps import optimise

    t0 = time.perf_counter()
    scene, inp = _start(scene_path, seed)
    load_s = time.perf_counter() - t0
    profiler = None
    if profile_to is not None:
        from pyinstrument import Profiler

        profiler = Profiler(interval=0.01)
        profiler.start()
    t0, c0 = time.perf_counter(), time.process_time()
    result = optimise(inp, OptimiseSettings.from_mapping(settings, "--settings"))
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    if profiler is not None:
        profiler.stop()
        assert profile_to is not None
        profile_to.write_text(profiler.output_text(unicode=True, color=False, show_all=False))
        profile_to.with_suffix(".html").write_text(profiler.output_html())
    iters = [h for h in result.history if h["iteration"] > 0]
    joint = [h for h in iters if h["stage"] != "light"]
    dx = np.linalg.norm(result.vertices - scene.vertices, axis=1)
    return {
        "vertices": len(scene.vertices),
        "views": scene.rig.n_views,
        "frames": scene.frames.count,
        "observations": result.n_observations,
        "load_s": load_s,
        "seconds": seconds,
        "solve_cpu_s": cpu,
        "iterations": len(iters),
        "iteration_s_mean": float(np.mean([h["seconds"] for h in iters])) if iters else None,
        "cg_iterations_mean": float(np.mean([h["cg_iterations"] for h in iters]))
        if iters
        else None,
        "cg_iterations_joint_mean": float(np.mean([h["cg_iterations"] for h in joint]))
        if joint
        else None,
        "joint_iteration_s_mean": float(np.mean([h["seconds"] for h in joint])) if joint else None,
        "stage_seconds": result.stage_seconds,
        "final_cost": result.history[-1]["terms"]["total"],
        "start_cost": result.history[0]["terms"]["total"],
        "history": [
            [h["stage"], h["outer"], h["iteration"], h["terms"]["total"], h["accepted"],
             h["cg_iterations"]]
            for h in result.history
        ],
        "light_error_m": float(np.linalg.norm(result.light[0] - scene.light_offset)),
        "vertex_error_mm_rms": float(np.sqrt(np.mean(dx**2)) * 1e3),
        "vertex_error_mm_median": float(np.median(dx) * 1e3),
        "vertex_error_mm_p95": float(np.percentile(dx, 95) * 1e3),
        "start_error_mm_median": float(
            np.median(np.linalg.norm(inp.vertices - scene.vertices, axis=1)) * 1e3
        ),
    }


def _joint_problem(scene_path: Path, seed: int) -> tuple[Any, np.ndarray, np.ndarray]:
    """The first joint stage's problem from the perturbed shape and a wrong light."""
    from reconstruct.optimise.cost import JointCost
    from reconstruct.optimise.problem_setup import build_problem, initial_reflectance
    from reconstruct.optimise.settings import OptimiseSettings

    scene, inp = _start(scene_path, seed)
    cfg = OptimiseSettings()
    light0 = (scene.light_offset + np.asarray(LIGHT_ERROR_M)).reshape(1, 3)
    problem = build_problem(inp, inp.vertices, light0, cfg)
    theta = problem.pack(inp.vertices, np.zeros((problem.n_vertices, problem.n_basis)), light0)
    alpha = initial_reflectance(problem, theta, inp.basis, cfg.init_smoothness)
    theta = problem.pack(inp.vertices, alpha, light0)
    return JointCost(problem), theta, problem.mask(True, True, True)


def worker_compare(
    scene_path: Path, seed: int, solver: str, target: float | None, budget_s: float
) -> dict[str, Any]:
    """One joint solve by ``ours`` or ``scipy`` (stops at ``target`` cost or the budget)."""
    cost, theta, mask = _joint_problem(scene_path, seed)
    start = cost.terms(theta)["total"]
    t0, c0 = time.perf_counter(), time.process_time()
    if solver == "ours":
        from reconstruct.optimise.solver import SolverSettings, levenberg_marquardt

        res = levenberg_marquardt(cost, theta, mask, SolverSettings(max_iterations=200))
        return {
            "solver": "ours",
            "seconds": time.perf_counter() - t0,
            "solve_cpu_s": time.process_time() - c0,
            "start_cost": start,
            "final_cost": res.terms["total"],
            "iterations": len(res.history),
            "stop": res.stop_reason,
            "observations": cost.p.obs.count,
            "parameters": int(theta.size),
        }
    from scipy.optimize import least_squares

    state = {"cost": start, "reached": False, "iterations": 0}

    def callback(intermediate_result: Any) -> None:
        state["iterations"] = int(state["iterations"]) + 1
        state["cost"] = 2.0 * float(intermediate_result.cost)  # scipy's cost is ½ Σ r²
        if target is not None and state["cost"] <= target * (1.0 + EQUAL_COST):
            state["reached"] = True
            raise StopIteration
        if time.perf_counter() - t0 > budget_s:
            raise StopIteration

    jac_seconds: list[float] = []

    def jac(x: np.ndarray) -> Any:
        t = time.perf_counter()
        j = cost.jacobian(x)
        jac_seconds.append(time.perf_counter() - t)
        return j

    from reconstruct.optimise.solver import keep_freed_memory

    with keep_freed_memory():  # the same allocator setting our solver runs under
        res = least_squares(
            cost.residuals,
            theta,
            jac=jac,
            method="trf",
            tr_solver="lsmr",
            x_scale="jac",
            ftol=1e-12,
            xtol=1e-12,
            gtol=1e-12,
            max_nfev=10_000,
            callback=callback,
        )
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    j0 = cost.jacobian(theta)
    return {
        "solver": "scipy",
        "seconds": seconds,
        "solve_cpu_s": cpu,
        "start_cost": start,
        "final_cost": 2.0 * float(res.cost),
        "iterations": int(state["iterations"]),
        "nfev": int(res.nfev),
        "njev": int(res.njev or 0),
        "jacobian_s_mean": float(np.mean(jac_seconds)) if jac_seconds else None,
        "jacobian_nnz": int(j0.nnz),
        "jacobian_shape": list(j0.shape),
        "reached_target": bool(state["reached"]),
        "stop": str(res.message),
    }


def worker(argv: list[str]) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("mode", choices=("prepare", "optimise", "compare"))
    p.add_argument("--cache", type=Path, required=True)
    p.add_argument("--vertices", type=int, required=True)
    p.add_argument("--views", type=int, required=True)
    p.add_argument("--width", type=int, required=True)
    p.add_argument("--height", type=int, required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--solver", choices=("ours", "scipy"), default="ours")
    p.add_argument("--target", type=float, default=None)
    p.add_argument("--budget", type=float, default=600.0)
    p.add_argument("--profile-to", type=Path, default=None)
    p.add_argument("--settings", default="{}", help="OptimiseSettings overrides (JSON)")
    a = p.parse_args(argv)
    from bench._scene import cached_scene

    t0 = time.perf_counter()
    path = cached_scene(a.cache, a.vertices, a.views, a.width, a.height, a.seed)
    if a.mode == "prepare":
        emit_worker_result({"scene": str(path), "seconds": time.perf_counter() - t0})
    elif a.mode == "optimise":
        emit_worker_result(worker_optimise(path, a.seed, a.profile_to, json.loads(a.settings)))
    else:
        emit_worker_result(worker_compare(path, a.seed, a.solver, a.target, a.budget))
    return 0


def _gb(mb: float) -> str:
    return f"{mb / 1024:.2f} GB"


def _grace(budget: float) -> float:
    """Kill a scipy worker whose iteration in flight runs this far past its budget."""
    return 1.5 * budget + 30.0


def _time(wall: float, cpu: float) -> str:
    return f"{wall:.1f} s ({cpu:.1f} s CPU)"


def tables(args: argparse.Namespace, runs: list[dict[str, Any]]) -> list[ResultTable]:
    """The result tables from the run records (also re-rendered from a saved JSON)."""
    t_main = ResultTable(
        f"Joint optimisation, paper steps (light stage + joint stages with shadow rebuilds), "
        f"{args.views} views × 2 illuminations, {args.width}×{args.height} images",
        [
            "vertices",
            "observations",
            "time to convergence (CPU)",
            "LM iterations",
            "s / iteration wall (CPU)",
            "CG its / iteration",
            "peak RSS",
            "final cost",
            "light error",
            "vertex error median / RMS (start 0.5 mm RMS)",
            "target (100k: ≤ 300 s, ≤ 4 GB)",
        ],
    )
    t_cmp = ResultTable(
        "One joint solve, same cost and start: ours (LM + PCG, matrix-free) vs "
        "scipy least_squares (trf, lsmr, sparse J)",
        [
            "vertices",
            "ours (CPU)",
            "ours cost (its)",
            "ours RSS",
            "scipy (CPU)",
            "scipy cost (its)",
            "scipy RSS",
            "J nnz",
            "scipy / ours wall (CPU)",
            "equal cost reached",
        ],
    )
    for run in runs:
        n = run["vertices"]
        r = run.get("optimise")
        if r is not None:
            met, capped = "", bool(r.get("capped", r.get("settings")))
            converged = [
                x["optimise"]
                for x in runs
                if x.get("optimise")
                and not x["optimise"].get("capped", x["optimise"].get("settings"))
            ]
            if capped and converged:  # time to convergence ≈ its to converge × this s/iteration
                its = converged[-1]["iterations"]
                est = its * r["solve_cpu_s"] / r["iterations"]
                time_cell = f"capped at {r['iterations']} its; est. {its} its ≈ {est:.0f} s CPU"
                cpu_to_converge = est
            else:
                time_cell = _time(r["seconds"], r.get("solve_cpu_s", float("nan")))
                cpu_to_converge = r.get("solve_cpu_s", float("nan"))
            if n == 100_000:
                ok = cpu_to_converge <= TARGET_S and r["peak_rss_mb"] <= TARGET_GB * 1024
                met = "met" if ok else "NOT met"
            t_main.add(
                n,
                r["observations"],
                time_cell,
                r["iterations"],
                f"{r['iteration_s_mean']:.2f} s "
                f"({r.get('solve_cpu_s', float('nan')) / max(r['iterations'], 1):.2f} s)",
                f"{r['cg_iterations_mean']:.1f}"
                + (
                    f" (joint {r['cg_iterations_joint_mean']:.1f})"
                    if r.get("cg_iterations_joint_mean")
                    else ""
                ),
                _gb(r["peak_rss_mb"]),
                f"{r['final_cost']:.5g}",
                "(capped)" if capped else f"{r['light_error_m'] * 1e3:.2f} mm",
                "(capped)"
                if capped
                else f"{r.get('vertex_error_mm_median', float('nan')):.3f} / "
                f"{r['vertex_error_mm_rms']:.3f} mm",
                met,
            )
        cmp = run.get("compare")
        if cmp is None:
            continue
        ours, sci = cmp["ours"], cmp["scipy"]
        ours_cells = [
            _time(ours["seconds"], ours["solve_cpu_s"]),
            f"{ours['final_cost']:.5g} ({ours['iterations']})",
            _gb(ours["peak_rss_mb"]),
        ]
        if sci is None:
            ratio = cmp["ratio_at_least"]
            t_cmp.add(
                n, *ours_cells, f"killed at {_grace(args.scipy_budget):.0f} s", "-", "-", "-",
                f"≥ {ratio:.1f}×", False,
            )  # fmt: skip
            continue
        at_least = "" if sci["reached_target"] else "≥ "
        t_cmp.add(
            n,
            *ours_cells,
            _time(sci["seconds"], sci["solve_cpu_s"]),
            f"{sci['final_cost']:.5g} ({sci['iterations']})",
            _gb(sci["peak_rss_mb"]),
            sci["jacobian_nnz"],
            f"{at_least}{sci['seconds'] / ours['seconds']:.1f}× "
            f"({at_least}{sci['solve_cpu_s'] / ours['solve_cpu_s']:.1f}×)",
            sci["reached_target"],
        )
    return [t for t in (t_main, t_cmp) if t.rows]


def notes(args: argparse.Namespace, blas: object) -> list[str]:
    return [
        f"start: true shape displaced along the normals by a smooth field of RMS "
        f"{PERTURB_M * 1e3:.1f} mm; paper steps start the light offset at 0 (camera "
        f"centre), the solver comparison at the true offset + {LIGHT_ERROR_M} m with α "
        "from the 2-D estimate",
        "cost = the paper's eq. 1 as Σ r² (rendering in 8-bit units); scipy's ½ Σ r² "
        "doubled; costs of the paper steps are of the last stage's observation set",
        f"scipy is stopped once its cost is within {EQUAL_COST:.0e} of ours, or after "
        f"{args.scipy_budget:.0f} s ('≥': it had not reached our cost by then)",
        "CPU = process CPU time (user + system, all threads): the load-independent figure on a "
        "shared machine; wall-clock times stretch with the machine's load",
        f"BLAS threads in the workers: {blas}",
    ]


def render(paths: list[Path], out: Path, console: Console) -> int:
    """Merge saved runs (later files win per size and part) and print their tables."""
    merged: dict[int, dict[str, Any]] = {}
    saved: dict[str, Any] = {}
    for path in paths:
        saved = json.loads(path.read_text())
        for run in saved["runs"]:
            merged.setdefault(run["vertices"], {}).update(run)
    old = argparse.Namespace(**saved["args"])
    runs = [merged[n] for n in sorted(merged)]
    blas = saved["machine"].get("blas_threads", "library default")
    payload = {"args": saved["args"], "runs": runs, "merged_from": [str(p) for p in paths]}
    report("solver", out, tables(old, runs), payload, saved["machine"], console, notes(old, blas))
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker(argv[1:])
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="25000,50000,100000,200000", help="vertex counts")
    parser.add_argument(
        "--scipy-sizes", default="5000,25000", help="sizes of the ours-vs-scipy joint solve"
    )
    parser.add_argument("--scipy-budget", type=float, default=900.0, help="seconds per scipy run")
    parser.add_argument("--views", type=int, default=40)
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--blas-threads", type=int, default=None, help="pin OpenBLAS/OpenMP threads in workers"
    )
    parser.add_argument("--profile", action="store_true", help="pyinstrument profile per size")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument(
        "--capped",
        type=int,
        default=None,
        help="per-iteration timing only: 1 outer stage, N light and N joint iterations",
    )
    parser.add_argument(
        "--render", type=Path, nargs="+", help="only re-print the tables of results JSON(s), merged"
    )
    parser.add_argument("--quick", action="store_true", help="smoke size")
    parser.add_argument(
        "--settings",
        default="{}",
        help='OptimiseSettings overrides (JSON), e.g. {"solver": {"cg_tolerance": 0.003}}',
    )
    args = parser.parse_args(argv)
    console = make_console()
    if args.render is not None:
        return render(args.render, args.out, console)
    settings: dict[str, Any] = {}
    if args.capped is not None:
        settings = {
            "outer_iterations": 1,
            "light_iterations": args.capped,
            "joint_iterations": args.capped,
        }
    if args.quick:
        args.sizes, args.scipy_sizes, args.views = "800", "800", 6
        args.width, args.height, args.scipy_budget = 120, 90, 10.0
        args.blas_threads = args.blas_threads or 1
        settings = {"outer_iterations": 1, "light_iterations": 4, "joint_iterations": 4}
    args.capped_run = bool(settings)
    args.settings = {**settings, **json.loads(args.settings)}
    sizes = [int(s) for s in args.sizes.split(",") if s]
    scipy_sizes = [int(s) for s in args.scipy_sizes.split(",") if s]
    info = machine_info()
    info["blas_threads"] = args.blas_threads or "library default"
    cache = args.out / "solver_cache"
    runs: list[dict[str, Any]] = []
    everything = sorted(set(sizes) | set(scipy_sizes))
    for n in everything:
        entry: dict[str, Any] = {"vertices": n}
        common = [
            "--cache", str(cache), "--vertices", str(n), "--views", str(args.views),
            "--width", str(args.width), "--height", str(args.height), "--seed", str(args.seed),
        ]  # fmt: skip
        console.print(f"[bold]{n:,} vertices[/]: preparing scene")
        entry["scene"] = run_worker(MODULE, ["prepare", *common])
        if n in sizes:
            entry["optimise"] = _paper_steps(args, n, common, console)
        if n in scipy_sizes:
            entry["compare"] = _compare(args, n, common, console)
        runs.append(entry)
        payload = {"args": {**vars(args), "out": str(args.out)}, "runs": runs}
        report(
            "solver",
            args.out,
            tables(args, runs),
            payload,
            info,
            console if n == everything[-1] else Console(quiet=True),
            notes(args, info["blas_threads"]),
        )
    return 0


MODULE = "bench.solver"


def _paper_steps(
    args: argparse.Namespace, n: int, common: list[str], console: Console
) -> dict[str, Any]:
    extra = ["--profile-to", str(args.out / f"solver_profile_{n}.txt")] if args.profile else []
    console.print(f"[bold]{n:,} vertices[/]: paper steps")
    extra += ["--settings", json.dumps(args.settings)]
    r = run_worker(MODULE, ["optimise", *common, *extra], blas_threads=args.blas_threads)
    return {**r, "settings": args.settings, "capped": args.capped_run}


def _compare(
    args: argparse.Namespace, n: int, common: list[str], console: Console
) -> dict[str, Any]:
    console.print(f"[bold]{n:,} vertices[/]: joint solve, ours")
    ours = run_worker(
        MODULE, ["compare", *common, "--solver", "ours"], blas_threads=args.blas_threads
    )
    console.print(f"[bold]{n:,} vertices[/]: joint solve, scipy least_squares")
    cmd = [
        "compare", *common, "--solver", "scipy",
        "--target", repr(ours["final_cost"]), "--budget", str(args.scipy_budget),
    ]  # fmt: skip
    try:
        sci = run_worker(
            MODULE, cmd, timeout_s=_grace(args.scipy_budget), blas_threads=args.blas_threads
        )
    except subprocess.TimeoutExpired:  # one scipy iteration outlasted the budget: killed
        return {
            "ours": ours,
            "scipy": None,
            "ratio_at_least": _grace(args.scipy_budget) / ours["seconds"],
        }
    return {"ours": ours, "scipy": sci, "ratio": sci["seconds"] / ours["seconds"]}


if __name__ == "__main__":
    sys.exit(main())
