"""The paper's simulation study (Sec. 4.1.2) on the sim rig.

Per scene (detailed ``blob`` and ``torus``, painted with the 24 ColorChecker reflectances): a sim
capture of ≥ 40 camera–light positions × 2 illuminations (LED1, LED2) with known poses (the paper
gives OpenMVS the true poses), the initial mesh of the pipeline's own CPU dense path
(PatchMatch + Poisson; ``--initial degraded`` is an ablation: the true shape re-sampled with
point noise and a smooth wave, re-meshed by Poisson), then

* (a) baseline "MVS + per-pixel estimation": 2-D reflectance per pixel of every image (the
  calibration module's estimator, shading taken as a flat white reference facing the light at the
  object's distance, as a 2-D method calibrates it), averaged per vertex of the initial mesh over
  its projections in all visible views;
* (b) the full joint method: ``rig reconstruct`` (``run_reconstruction``) from the same mesh;
* oracle: true shape and true light positions, reflectance per vertex by least squares from the
  same images (shadows and shading known);
* information floor: the 2-D estimator on noise-free responses of each true reflectance under
  the session's illuminations and camera (shading known) — the physical limit of the data.

Each method is scored by spectral RMSE and CIEDE2000 under D65 and A (per vertex and per
ColorChecker patch).

Each runs in its own interpreter (its own peak RSS) and is scored by
``reconstruct.outputs.evaluate``.

    python -m bench.paper_sim              # blob + torus, 40 views, 640x480
    python -m bench.paper_sim --quick      # smoke size
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from rich.console import Console

from bench._common import (
    COLOUR_COLUMNS,
    DEFAULT_OUT,
    ResultTable,
    colour_cells,
    emit_worker_result,
    information_floor,
    machine_info,
    make_console,
    report,
    run_worker,
)

MODULE = "bench.paper_sim"
ILLUMINATIONS = ("LED1", "LED2")


# --- setup -------------------------------------------------------------------------------


def write_profile(
    path: Path,
    scene: str,
    views: int,
    width: int,
    height: int,
    subdiv: int,
    distances_m: tuple[float, ...] = (),
) -> Path:
    """The shipped sim profile: two illuminations, known poses, the benchmark's scene/size;
    ``distances_m`` steps the camera in and out between views (hand-held)."""
    from rig.profile import resolve_profile

    data = yaml.safe_load(resolve_profile("sim").read_text())
    data["illuminations"] = {k: data["illuminations"][k] for k in ILLUMINATIONS}
    data["plan"]["views"] = views
    data["plan"]["illuminations"] = "all"
    data["poses"] = "known"
    data.pop("board", None)  # the paper's objects float: no marker board / ground plane
    data["sim"] = {
        **dict(data.get("sim") or {}),
        "scene": scene,
        "subdivisions": subdiv,
        # the sim's default field of view (800 px focal at 640 px wide) at any image size
        "camera": {"width": width, "height": height, "focal_px": 800.0 * width / 640.0},
    }
    if distances_m:
        trajectory = dict(data["sim"].get("trajectory") or {})
        data["sim"]["trajectory"] = {**trajectory, "distances_m": list(distances_m)}
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def do_capture(profile: Path, session: Path, seed: int) -> dict[str, Any]:
    import io

    from rig.capture import run_capture

    shutil.rmtree(session, ignore_errors=True)
    t0 = time.perf_counter()
    run_capture(profile, session, yes=True, seed=seed, console=Console(file=io.StringIO()))
    return {"seconds": time.perf_counter() - t0}


def do_initial(session: Path, out: Path, depth: int, points: int, seed: int) -> dict[str, Any]:
    """The true shape as an MVS-quality mesh (Poisson of noisy, wavy samples)."""
    from reconstruct.optimise.synthetic import mvs_like_mesh
    from reconstruct.outputs.evaluate import load_mesh

    t0 = time.perf_counter()
    gt = load_mesh(session / "ground_truth" / "mesh.ply")
    mesh = mvs_like_mesh(gt, points=points, depth=depth, seed=seed)
    mesh.export(out, encoding="binary")
    return {"seconds": time.perf_counter() - t0, "vertices": len(mesh.vertices)}


# --- methods -------------------------------------------------------------------------------


def _truth(session: Path) -> tuple[Path, Path, np.ndarray, np.ndarray]:
    gt = session / "ground_truth"
    rig = yaml.safe_load((gt / "rig.yaml").read_text())
    return (
        gt / "mesh.ply",
        gt / "reflectance.npy",
        np.asarray(rig["light_offset_m"], dtype=float),
        np.asarray(rig["light_positions_m"], dtype=float),
    )


def _inputs(session: Path, initial: Path | None, config: dict[str, Any]) -> tuple[Any, Any]:
    """The decoded frames, rig and calibration as the optimiser sees them (stages cached)."""
    from calibration.basis import default_basis
    from core.session import Session
    from reconstruct.optimise.settings import OptimiseSettings
    from reconstruct.run.front import run_front
    from reconstruct.run.pipeline import optimiser_input

    opened = Session.open(session)
    # glossy as the reconstruction had it, or the front end's stages would be built again
    glossy = OptimiseSettings.from_mapping(config.get("optimise")).glossy
    front_conf = {k: v for k, v in config.items() if k != "optimise"}
    front = run_front(opened, front_conf, initial, glossy=glossy)
    return front, optimiser_input(front, opened, default_basis())


def _score(
    session: Path, npz: Path, out: Path, light_positions: np.ndarray | None, offset: bool
) -> dict[str, Any]:
    """reconstruct.outputs.evaluate's metrics plus the median spectral RMSE and the light error."""
    from reconstruct.outputs import export
    from reconstruct.outputs.evaluate import evaluate

    gt_mesh, gt_refl, gt_offset, gt_lights = _truth(session)
    ev = evaluate(npz, gt_mesh, gt_refl, gt_offset if offset else None, out)
    ev.files.append(str(accuracy_map(npz, gt_mesh, out / "accuracy_error_map.png")))
    rmse = np.load(out / "spectral_rmse_per_vertex.npy")
    observed = np.asarray(export.read_reflectance_npz(npz).get("observed", np.ones(len(rmse))))
    light_err = None
    if light_positions is not None:
        light_err = float(np.mean(np.linalg.norm(light_positions - gt_lights, axis=1)))
    return {
        "accuracy_m": ev.accuracy_m,
        "completeness_m": ev.completeness_m,
        "rmse_mean": ev.spectral_rmse,
        "rmse_median": float(np.median(rmse[observed.astype(bool)])),
        "colour": ev.colour,
        "outside_unit_range": ev.outside_unit_range,
        "light_offset_error_m": ev.light_offset_error_m,
        "light_position_error_m": light_err,
        "vertices": ev.vertices,
        "observed_vertices": ev.observed_vertices,
        "files": ev.files,
    }


def accuracy_map(npz: Path, gt_mesh: Path, path: Path, vmax_m: float = 0.002) -> Path:
    """Mesh coloured by each vertex's distance to the true surface (viridis, 0 … 2 mm), two
    views lit from the eye — the paper's accuracy error maps."""
    import matplotlib

    from reconstruct.model.camera import Intrinsics, Pose
    from reconstruct.model.raycast import RayCaster
    from reconstruct.model.render import render_image
    from reconstruct.outputs import export, plots
    from reconstruct.outputs.evaluate import load_mesh, surface_distance
    from reconstruct.outputs.relight import encode_srgb

    data = export.read_reflectance_npz(npz)
    X, F = np.asarray(data["vertices"], dtype=float), np.asarray(data["faces"], dtype=np.int64)
    dist, _, _ = surface_distance(X, load_mesh(gt_mesh))
    colours = matplotlib.colormaps["viridis"](np.clip(dist / vmax_m, 0.0, 1.0))[:, :3]
    centre = X.mean(axis=0)
    radius = float(np.max(np.linalg.norm(X - centre, axis=1)))
    caster = RayCaster(X, F)
    intr = Intrinsics.pinhole(400, 400, 640.0)
    tiles = []
    for direction in ((1.0, 0.6, 0.5), (-1.0, -0.6, 0.3)):
        eye = centre + 3.5 * radius * np.asarray(direction) / np.linalg.norm(direction)
        img, cover = render_image(
            X, F, colours, intr, Pose.look_at(eye, centre), eye,
            np.eye(3) * (3.5 * radius) ** 2, caster=caster,
        )  # fmt: skip
        tiles.append(encode_srgb(img + (1.0 - cover[..., None])))
    title = f"accuracy: distance to the true surface per vertex (0 … {vmax_m * 1e3:.1f} mm)"
    return plots.image(path, np.concatenate(tiles, axis=1), title)


def _write_npz(
    path: Path, X: np.ndarray, F: np.ndarray, refl: np.ndarray, seen: np.ndarray
) -> Path:
    from calibration.basis import default_basis
    from reconstruct.optimise.mesh import vertex_normals
    from reconstruct.outputs import export

    basis = default_basis()
    normals, _ = vertex_normals(X, F)
    fill = np.where(np.isfinite(refl), refl, np.nanmean(refl[seen], axis=0))
    return export.write_reflectance_npz(
        path, X, F, normals, basis.wavelengths_nm, fill, basis.project(fill), basis.B, seen
    )


def _visible_samples(
    vertices: np.ndarray, faces: np.ndarray, inp: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertex, frame, uv) for every vertex seen by a frame's camera, on valid pixels."""
    import trimesh

    from reconstruct.geometry.visibility import compute_visibility
    from reconstruct.optimise.sampling import taps_valid

    rig, fr = inp.rig, inp.frames
    views = range(rig.n_views)
    vis = compute_visibility(
        trimesh.Trimesh(vertices, faces, process=False),
        dict(zip(views, rig.intrinsics, strict=True)),
        dict(zip(views, rig.poses, strict=True)),
    )
    vi, col = vis.pairs()
    rows, frames, uvs = [], [], []
    for f in range(fr.count):
        c = int(fr.view[f])
        v = vi[np.asarray(vis.views)[col] == c]
        uv = rig.intrinsics[c].project_camera(rig.poses[c].to_camera(vertices[v]))
        ok = taps_valid(fr.valid, np.full(len(v), f), uv, 1.0)
        rows.append(v[ok])
        frames.append(np.full(int(ok.sum()), f))
        uvs.append(uv[ok])
    return np.concatenate(rows), np.concatenate(frames), np.concatenate(uvs)


def do_baseline(
    session: Path, initial: Path | None, out: Path, config: dict[str, Any]
) -> dict[str, Any]:
    """(a) per-pixel 2-D estimation on every frame, averaged per vertex of the initial mesh."""
    from calibration.estimation import estimate_reflectance
    from reconstruct.optimise.sampling import bilinear
    from reconstruct.outputs.evaluate import load_mesh

    t0 = time.perf_counter()
    front, inp = _inputs(session, initial, config)
    mesh = load_mesh(front.initial_mesh_path)
    X, F = np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)
    rig, fr = inp.rig, inp.frames
    centre = X.mean(axis=0)
    _, _, offset, _ = _truth(session)
    n_ill = rig.responses.shape[0]
    # Per view: reflectance image from its frames (one per illumination), shading of a flat
    # white reference facing the light at the object's distance.
    refl_img: dict[int, np.ndarray] = {}
    for c in range(rig.n_views):
        idx = [
            int(np.flatnonzero((fr.view == c) & (fr.illumination == k))[0]) for k in range(n_ill)
        ]
        rgb = np.stack([fr.images[i] for i in idx], axis=2)  # (H, W, K, 3)
        h, w = rgb.shape[:2]
        rgb = rgb.reshape(h * w, n_ill, 3).astype(float)
        bad = ~np.stack([fr.valid[i] for i in idx], axis=2).reshape(h * w, n_ill)
        rgb[bad] = np.nan
        d = np.linalg.norm(rig.poses[c].light_position(offset) - centre)
        rgb *= d**2  # a white reference at the object's distance reads 1/d²: normalise by it
        r = np.full((h * w, inp.basis.B.shape[0]), np.nan)
        full = ~bad.any(axis=1)  # the linear estimator at once; pixels with a gap one by one
        for rows in (full, ~full):
            if rows.any():
                r[rows] = estimate_reflectance(rgb[rows], rig.responses, inp.basis)[1]
        refl_img[c] = r.reshape(h, w, -1).astype(np.float32)
    v, f, uv = _visible_samples(X, F, inp)
    # One sample per (vertex, view): take each view's reflectance image once.
    view = fr.view[f]
    pair = v * rig.n_views + view
    _, keep = np.unique(pair, return_index=True)
    v, view, uv = v[keep], view[keep], uv[keep]
    stack = np.stack([refl_img[c] for c in range(rig.n_views)])
    values, _ = bilinear(stack, view, uv)
    ok = np.all(np.isfinite(values), axis=1)
    nl = stack.shape[-1]
    total = np.zeros((len(X), nl))
    count = np.zeros(len(X))
    np.add.at(total, v[ok], values[ok])
    np.add.at(count, v[ok], 1.0)
    seen = count > 0
    refl = np.full((len(X), nl), np.nan)
    refl[seen] = total[seen] / count[seen, None]
    npz = _write_npz(out / "reflectance.npz", X, F, refl, seen)
    seconds = time.perf_counter() - t0
    return {"seconds": seconds, **_score(session, npz, out, None, offset=False)}


def do_joint(
    session: Path, initial: Path | None, out: Path, config: dict[str, Any]
) -> dict[str, Any]:
    """(b) the full pipeline (front stages + joint optimisation + export)."""
    from reconstruct.run.pipeline import run_reconstruction

    # A finished optimisation checkpoint of an earlier run would be resumed, not timed.
    shutil.rmtree(session / "recon" / "optimise", ignore_errors=True)
    t0 = time.perf_counter()
    rec = run_reconstruction(session, config, initial)
    seconds = time.perf_counter() - t0
    positions = np.asarray(rec.report["light"]["positions_m"], dtype=float)
    out.mkdir(parents=True, exist_ok=True)
    score = _score(session, rec.reflectance_path, out, positions, offset=True)
    return {
        "seconds": seconds,
        "timings_s": rec.report.get("timings_s", {}),
        "observations": rec.report.get("observations"),
        **score,
    }


def do_oracle(
    session: Path, initial: Path | None, out: Path, config: dict[str, Any]
) -> dict[str, Any]:
    """True shape and light; α per vertex by least squares over its observations."""
    from calibration.estimation import estimate_reflectance
    from reconstruct.model.forward import shading
    from reconstruct.model.raycast import RayCaster
    from reconstruct.optimise.mesh import vertex_normals
    from reconstruct.optimise.sampling import bilinear
    from reconstruct.optimise.settings import OptimiseSettings
    from reconstruct.outputs.evaluate import load_mesh

    t0 = time.perf_counter()
    _, inp = _inputs(session, initial, config)
    gt_mesh, _, _, gt_lights = _truth(session)
    gt = load_mesh(gt_mesh)
    X, F = np.asarray(gt.vertices, dtype=float), np.asarray(gt.faces, dtype=np.int64)
    rig, fr = inp.rig, inp.frames
    normals, _ = vertex_normals(X, F)
    v, f, uv = _visible_samples(X, F, inp)
    view = fr.view[f]
    s = shading(X[v], normals[v], gt_lights[view])
    # as the optimiser: no grazing views (their bilinear taps straddle the silhouette)
    centres = np.stack([pose.center for pose in rig.poses])[view]
    to_cam = centres - X[v]
    cos_view = np.einsum("ij,ij->i", normals[v], to_cam) / np.linalg.norm(to_cam, axis=1)
    lit = (s > 0) & (cos_view >= OptimiseSettings().min_view_cos)
    pv = np.unique(v * rig.n_views + view)
    blocked = RayCaster(X, F).occluded(
        X[pv // rig.n_views], gt_lights[pv % rig.n_views], 1e-4, normals[pv // rig.n_views]
    )
    lit &= ~np.isin(v * rig.n_views + view, pv[blocked])
    v, f, uv, s = v[lit], f[lit], uv[lit], s[lit]
    y, _ = bilinear(fr.images, f, uv)
    k = fr.illumination[f]
    n, n_ill = len(X), rig.responses.shape[0]
    s2 = np.zeros((n, n_ill))
    sy = np.zeros((n, n_ill, 3))
    np.add.at(s2, (v, k), s**2)
    np.add.at(sy, (v, k), s[:, None] * y)
    seen2 = s2 > 0
    root = np.sqrt(s2)
    rgb = np.full((n, n_ill, 3), np.nan)
    rgb[seen2] = sy[seen2] / root[seen2][:, None]
    # every illumination seen: a vertex whose other frames all clip has no estimate to score
    seen = np.asarray(seen2.all(axis=1), dtype=bool)
    refl = np.full((n, inp.basis.B.shape[0]), np.nan)
    _, refl[seen] = estimate_reflectance(rgb[seen], rig.responses, inp.basis, shading=root[seen])
    npz = _write_npz(out / "reflectance.npz", X, F, refl, seen)
    seconds = time.perf_counter() - t0
    return {"seconds": seconds, **_score(session, npz, out, gt_lights, offset=False)}


# --- driver --------------------------------------------------------------------------------


def worker(argv: list[str]) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("mode", choices=("capture", "initial", "baseline", "joint", "oracle"))
    p.add_argument("--session", type=Path, required=True)
    p.add_argument("--profile", type=Path)
    p.add_argument("--initial", type=Path)
    p.add_argument("--out", type=Path)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--depth", type=int, default=7)
    p.add_argument("--points", type=int, default=60000)
    p.add_argument("--config", default="{}", help="reconstruct config (JSON)")
    a = p.parse_args(argv)
    if a.mode == "capture":
        result = do_capture(a.profile, a.session, a.seed)
    elif a.mode == "initial":
        result = do_initial(a.session, a.initial, a.depth, a.points, a.seed)
    else:
        a.out.mkdir(parents=True, exist_ok=True)
        method = {"baseline": do_baseline, "joint": do_joint, "oracle": do_oracle}[a.mode]
        result = method(a.session, a.initial, a.out, json.loads(a.config))
    emit_worker_result(result)
    return 0


def _mm(value: float | None) -> str:
    return "-" if value is None else f"{value * 1e3:.3f} mm"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker(argv[1:])
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", default="blob,torus")
    parser.add_argument("--views", type=int, default=40, help="camera–light positions")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--subdivisions", type=int, default=7, help="sim scene detail")
    parser.add_argument(
        "--initial", choices=("dense", "degraded"), default="dense",
        help="initial mesh: the pipeline's own CPU dense path (default), or, as an ablation, "
        "the true shape re-sampled and Poisson-meshed",
    )  # fmt: skip
    parser.add_argument(
        "--distances", default="0.35,0.5,0.65",
        help="camera distances (m) cycled over the views, as a hand-held capture steps in and "
        "out; '' for one ring at the profile's radius",
    )  # fmt: skip
    parser.add_argument("--poisson-depth", type=int, default=7)
    parser.add_argument(
        "--max-faces", type=int, default=None, help="cap of the subdivided mesh (pipeline default)"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--quick", action="store_true", help="smoke size")
    args = parser.parse_args(argv)
    if args.quick:
        args.scenes, args.views, args.subdivisions = "blob", 6, 4
        args.width, args.height, args.poisson_depth, args.max_faces = 128, 96, 5, 20000
    info = machine_info()
    console = make_console()
    work = args.out / "paper_sim"
    columns = [
        "scene",
        "method",
        "vertices",
        "accuracy",
        "completeness",
        "spectral RMSE mean",
        "spectral RMSE median",
        *COLOUR_COLUMNS,
        "light position error",
        "time",
        "peak RSS",
    ]
    table = ResultTable(
        f"Paper Sec. 4.1.2 on the sim rig: {args.views} camera–light positions × "
        f"{len(ILLUMINATIONS)} illuminations, {args.width}×{args.height}, camera distances "
        f"{args.distances or 'one ring'} m, initial mesh: {args.initial}",
        columns,
    )
    config: dict[str, Any] = {}
    if args.quick:
        config["optimise"] = {"outer_iterations": 1, "light_iterations": 3, "joint_iterations": 3}
    if args.max_faces is not None:
        config["subdivide"] = {"max_faces": args.max_faces}
    runs: dict[str, Any] = {}
    for scene in [s for s in args.scenes.split(",") if s]:
        folder = work / scene
        folder.mkdir(parents=True, exist_ok=True)
        session = folder / "session"
        profile = write_profile(
            folder / "profile.yaml",
            scene,
            args.views,
            args.width,
            args.height,
            args.subdivisions,
            tuple(float(d) for d in args.distances.split(",") if d),
        )
        console.print(f"[bold]{scene}[/]: capture ({args.views * len(ILLUMINATIONS)} frames)")
        cap = run_worker(
            MODULE,
            [
                "capture",
                "--session",
                str(session),
                "--profile",
                str(profile),
                "--seed",
                str(args.seed),
            ],
        )
        initial: Path | None = None
        init: dict[str, Any] = {}
        if args.initial == "degraded":
            initial = folder / "initial_mvs.ply"
            init = run_worker(
                MODULE,
                ["initial", "--session", str(session), "--initial", str(initial),
                 "--depth", str(args.poisson_depth), "--seed", str(args.seed)],
            )  # fmt: skip
        scene_runs: dict[str, Any] = {"capture": cap, "initial": init}
        for mode, label in (
            ("joint", "(b) joint method (ours)"),
            ("baseline", "(a) initial mesh + per-pixel 2-D"),
            ("oracle", "oracle: true shape + light, per-vertex LS"),
        ):
            console.print(f"[bold]{scene}[/]: {label}")
            cmd = [mode, "--session", str(session), "--out", str(folder / mode)]
            cmd += ["--config", json.dumps(config)]
            if initial is not None:
                cmd += ["--initial", str(initial)]
            r = run_worker(MODULE, cmd)
            scene_runs[mode] = r
            oracle = mode == "oracle"
            table.add(
                scene,
                label,
                r["vertices"],
                "0 (truth)" if oracle else _mm(r["accuracy_m"]),
                "0 (truth)" if oracle else _mm(r["completeness_m"]),
                f"{r['rmse_mean']:.4f}",
                f"{r['rmse_median']:.4f}",
                *colour_cells(r["colour"]),
                _mm(r["light_position_error_m"]) if mode != "baseline" else "-",
                f"{r['seconds']:.1f} s",
                f"{r['peak_rss_mb'] / 1024:.2f} GB",
            )
        floor = information_floor(session)
        scene_runs["floor"] = floor
        table.add(
            scene, "information floor: 2-D estimator, true shading, no noise", "-", "-", "-",
            f"{floor['rmse_mean']:.4f}", f"{floor['rmse_median']:.4f}",
            *colour_cells(floor["colour"]), "-", "-", "-",
        )  # fmt: skip
        runs[scene] = scene_runs
        for mode in ("joint", "baseline", "oracle"):
            for png in (folder / mode).glob("*.png"):
                shutil.copy(png, args.out / f"paper_sim_{scene}_{mode}_{png.name}")
    notes = [
        "accuracy: mean distance reconstructed vertices → true surface; completeness: true "
        "vertices → reconstructed surface (reconstruct.outputs.evaluate)",
        "spectral RMSE: per vertex over 400–700 nm against the true reflectance at the closest "
        "true surface point, over observed vertices",
        "ΔE00: CIEDE2000 (CIE 1931 2°) under D65 and A, per vertex over observed vertices and "
        "per ColorChecker patch (the patch's median spectrum); information floor: the 2-D "
        "estimator given the true shading on noise-free responses of the true reflectance",
        "light position error: mean over views of |p_c − p_c,true| (the joint method's light "
        "comes from the plate offset, started at 0)",
        "time: each method from decoded inputs (cached front stages) to its scores; the joint "
        "row includes the front stages (decode, visibility, subdivision) and export",
        "error maps: OUT/paper_sim_<scene>_<method>_{spectral,accuracy}_error_map.png",
    ]
    report(
        "paper_sim",
        args.out,
        [table],
        {"args": {**vars(args), "out": str(args.out)}, "runs": runs},
        info,
        console,
        notes,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
