"""`rig demo`: simulated capture of the built-in scene → reconstruction → evaluation against
the truth, in minutes, printing a table and where the outputs are."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from core.errors import RigError
from rig.cliargs import MAX_VIEWS, SEED_MAX, number
from rig.outpaths import output_dir


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "demo",
        help="run the whole pipeline on the simulated rig",
        description="Capture the built-in scene with the simulated rig (real Bayer DNGs), "
        "reconstruct mesh, spectral reflectance and light offset, and evaluate against the "
        "simulator's ground truth.",
    )
    parser.add_argument("--out", type=Path, default=Path("rig-demo"), help="output folder")
    parser.add_argument("--views", type=int, default=20, help="camera positions (default 20)")
    parser.add_argument("--seed", type=number(int, min=0, max=SEED_MAX), default=0,
                        help="scene and noise seed")
    parser.set_defaults(func=handle)


def handle(args: argparse.Namespace) -> int:
    from contextlib import ExitStack

    import numpy as np
    import yaml
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Table

    from core.session import Session
    from reconstruct.model.camera import read_colmap_text
    from reconstruct.outputs.evaluate import colour_rows, evaluate, information_floor
    from reconstruct.run.logfile import run_logged
    from reconstruct.run.pipeline import session_responses
    from rig.capture import run_capture
    from rig.console import console as plain_console
    from rig.demo_profile import demo_profile
    from rig.next_steps import next_commands
    from rig.progress_lines import ProgressLines
    from rig.warmup import compile_kernels_once

    if not 6 <= args.views <= MAX_VIEWS:
        raise RigError(f"--views {args.views} is out of range",
                       f"allowed: a whole number in [6, {MAX_VIEWS}] (default 20)")
    out = output_dir(Path(args.out), "--out").resolve()
    session = out / "session"
    if session.exists():
        raise RigError(f"{session} already exists", "choose another --out or remove the folder")
    out.mkdir(parents=True, exist_ok=True)
    console = plain_console(stderr=True)
    profile_path = out / "demo-profile.yaml"
    profile_path.write_text(yaml.safe_dump(demo_profile(args.views), sort_keys=False))
    config = {
        "subdivide": {"max_faces": 60000},
        "optimise": {"outer_iterations": 2, "light_iterations": 10, "joint_iterations": 8},
    }
    compile_kernels_once(console)
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    with ExitStack() as stack:
        # live bars on a terminal; on a log or pipe, plain lines every 30 s
        bar = stack.enter_context(Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            TimeElapsedColumn(),
            console=console,
            transient=False,
            disable=not console.is_terminal,
        ))
        lines = None if console.is_terminal else stack.enter_context(
            ProgressLines(console, recon_dir=session / "recon")
        )

        def step(description: str, advance: int) -> None:
            bar.update(task, advance=advance, description=description)
            if lines is not None:
                lines.step(description)

        task = bar.add_task("demo: simulated capture", total=3)
        step("demo: simulated capture", 0)
        t = time.perf_counter()
        with open(out / "capture.txt", "w", encoding="utf-8") as capture_log:
            # the per-view prompts are for a person holding the camera: shown with -v only
            prompts = console if args.verbose else plain_console(file=capture_log, width=100)
            run_capture(profile_path, session, yes=True, seed=args.seed, console=prompts)
        timings["capture"] = time.perf_counter() - t
        step("demo: reconstruction", 1)
        t = time.perf_counter()
        rec = run_logged(session, config, None, args.verbose, console)
        timings["reconstruction"] = time.perf_counter() - t
        step("demo: evaluation", 1)
        t = time.perf_counter()
        truth = session / "ground_truth"
        rig = yaml.safe_load((truth / "rig.yaml").read_text())
        offset = rig.get("light_offset_m")
        ev = evaluate(
            rec.recon_dir,
            truth / "mesh.ply",
            truth / "reflectance.npy",
            None if offset is None else np.asarray(offset, dtype=float),
        )
        floor = information_floor(
            truth / "reflectance.npy", session_responses(Session.open(session))
        )
        timings["evaluation"] = time.perf_counter() - t
        step("demo: done", 1)
    initial = initial_accuracy(Path(rec.report["initial_mesh"]), truth / "mesh.ply")
    pose_source, centre_mm, rotation_deg = pose_errors(rec.recon_dir / "poses", truth / "poses")
    table = Table(title="rig demo: reconstruction vs simulator truth")
    table.add_column("metric")
    table.add_column("value", justify="right")
    for key, value in ev.table():
        table.add_row(key, value)
    # how far from the physical limit: the 2-D estimator given the true shading, no noise
    table.add_row("information floor: spectral RMSE", f"{floor['rmse_mean']:.4f}")
    for key, value in colour_rows(floor["colour"]):
        table.add_row(f"information floor: {key}", value)
    if offset is not None and ev.light_offset_m is not None:
        table.add_row("light offset: estimate", _cm(ev.light_offset_m))
        table.add_row("light offset: truth", _cm(offset))
    table.add_row(f"poses ({pose_source}): camera centre error mean / max", centre_mm)
    table.add_row(f"poses ({pose_source}): rotation error mean / max", rotation_deg)
    for key, seconds in timings.items():
        table.add_row(f"time: {key}", f"{seconds:.0f} s")
    table.add_row("time: total", f"{time.perf_counter() - t0:.0f} s")
    table.add_row(
        "accuracy of the initial mesh (MVS, before optimisation)", f"{initial * 1e3:.3f} mm"
    )
    out_console = plain_console()
    out_console.print(table)
    out_console.print(f"session:        {session}")
    out_console.print(f"reconstruction: {rec.recon_dir} (mesh.ply, reflectance.npz, report.json)")
    out_console.print(f"plots:          {', '.join(p.name for p in rec.plots)}")
    out_console.print(f"evaluation:     {', '.join(Path(f).name for f in ev.files)}")
    posed = sorted(read_colmap_text(rec.recon_dir / "poses")[1])
    out_console.print(f"output folder:  {out}", soft_wrap=True)
    out_console.print("next:")
    for command, what in next_commands(out, posed[0] - 1 if posed else 0):
        # one line each, never wrapped: a log keeps commands that can be pasted
        out_console.print(f"  {command:<60}  {what}", soft_wrap=True)
    return 0


def initial_accuracy(initial: Path, truth: Path) -> float:
    """Mean distance from the initial (subdivided MVS) mesh's vertices to the true surface."""
    import numpy as np

    from reconstruct.outputs.evaluate import load_mesh, surface_distance

    mesh = load_mesh(initial)
    distance, _, _ = surface_distance(np.asarray(mesh.vertices, dtype=float), load_mesh(truth))
    return float(np.mean(distance))


def pose_errors(estimated: Path, truth: Path) -> tuple[str, str, str]:
    """Estimated poses (recon/poses) against the simulator's, matched by image name: camera
    centre and rotation errors. Poses with a relative scale are first aligned to the truth by a
    similarity (Umeyama); metric poses (board, known) are compared as they are."""
    import numpy as np

    from reconstruct.model.camera import read_colmap_text
    from reconstruct.poses.board import umeyama
    from reconstruct.poses.output import SUMMARY as POSE_SUMMARY

    summary = json.loads((estimated / POSE_SUMMARY).read_text())
    _, est_images = read_colmap_text(estimated)
    _, true_images = read_colmap_text(truth)
    est = {name: pose for _, name, pose in est_images.values()}
    true = {name: pose for _, name, pose in true_images.values()}
    names = sorted(set(est) & set(true))
    if not names:
        return summary["source"], "no view posed", "no view posed"
    poses = [est[n] for n in names]
    if summary["scale"] != "metric" and len(names) >= 3:
        align = umeyama(
            np.array([p.center for p in poses]), np.array([true[n].center for n in names])
        )
        poses = [align.apply_pose(p) for p in poses]
    centre = np.array(
        [np.linalg.norm(p.center - true[n].center) for p, n in zip(poses, names, strict=True)]
    )
    cosines = [(np.trace(p.R @ true[n].R.T) - 1) / 2 for p, n in zip(poses, names, strict=True)]
    angle = np.degrees(np.arccos(np.clip(cosines, -1.0, 1.0)))
    return (
        f"{summary['source']}, {len(names)} views",
        f"{centre.mean() * 1e3:.2f} / {centre.max() * 1e3:.2f} mm",
        f"{angle.mean():.3f} / {angle.max():.3f}°",
    )


def _cm(v: Any) -> str:
    return "(" + ", ".join(f"{float(x) * 100:.2f}" for x in v) + ") cm"
