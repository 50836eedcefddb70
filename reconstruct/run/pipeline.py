"""``rig reconstruct`` as a library call: the front stages (decode → poses → initial mesh →
visibility → subdivide), the joint optimisation, and the files of ``SESSION/recon/``.

Config (YAML, all optional): the front's sections ``decode``, ``poses``, ``mesh``,
``procam``, ``visibility``, ``subdivide``, ``resolution`` (each stage's pyramid level,
:mod:`reconstruct.stages.resolution`) and ``optimise`` (:class:`OptimiseSettings`, with
``solver``). On projector sessions the front recovers one light position per view; the
optimiser then starts from them and, unless ``optimise.light_mode`` says otherwise, keeps them
fixed (``fixed``) as the paper does.

A run is tracked in ``recon/status.json`` (:mod:`reconstruct.run.status`), the optimisation
resumes from ``recon/optimise/checkpoint.npz`` (:mod:`reconstruct.optimise.checkpoint`) and the
outputs are swapped in as one set (:mod:`reconstruct.stages.publish`), so a kill at any instant
loses at most the stage in progress and never leaves old and new outputs mixed.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibration.basis import SpectralBasis, default_basis
from calibration.estimation import response_matrices
from calibration.grid import DEFAULT_GRID
from calibration.store import CalibrationStore
from core.errors import RigError
from core.labels import AMBIENT
from core.lock import locked
from core.session import Session
from core.yamlio import read_yaml
from reconstruct.frames.ambient import exposure_ratio, subtract_ambient
from reconstruct.frames.decode import FLOAT16_RANGE, drop_frames, frame_bytes, load_frame
from reconstruct.frames.pyramid import downsample, downsample_mask
from reconstruct.model.camera import Intrinsics
from reconstruct.model.raycast import RayCaster
from reconstruct.optimise.checkpoint import FILE as CHECKPOINT_FILE
from reconstruct.optimise.checkpoint import Checkpoint, input_key
from reconstruct.optimise.mesh import vertex_normals
from reconstruct.optimise.problem import Frames, Rig
from reconstruct.optimise.settings import OptimiseInput, OptimiseSettings
from reconstruct.optimise.solver import IterationRecord
from reconstruct.optimise.steps import OptimiseResult, optimise
from reconstruct.outputs import export, plots
from reconstruct.outputs.relight import Camera, encode_srgb, relight
from reconstruct.run.front import FrontConfig, FrontResult, run_front
from reconstruct.run.status import RunStatus, tracked
from reconstruct.stages.disk import stage_sizes_mb
from reconstruct.stages.memory import (
    memory_within_reach_gb,
    peak_rss_mb,
    reset_peak_rss,
    solve_memory_gb,
)
from reconstruct.stages.publish import publish, staging_dir
from reconstruct.stages.resolution import level_size
from reconstruct.stages.resumable import Timings, timed_run

log = logging.getLogger("reconstruct")
FRONT_SECTIONS = ("decode", "poses", "mesh", "procam", "visibility", "subdivide", "resolution")
Progress = Callable[[str, IterationRecord], None]
RECONSTRUCT = "rig reconstruct"  # what a refused command is told holds the session


@dataclass
class Reconstruction:
    recon_dir: Path
    mesh_path: Path
    reflectance_path: Path
    report_path: Path
    plots: list[Path]
    result: OptimiseResult
    report: dict[str, Any]


def load_config(path: Path | None) -> dict[str, Any]:
    """The reconstruct config file as a mapping (empty without a file)."""
    if path is None:
        return {}
    data = read_yaml(Path(path), "config", "fix the YAML syntax (indentation, repeated keys)")
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise RigError(f"config {path} is not a mapping", "write sections like `optimise: {...}`")
    unknown = set(data) - {*FRONT_SECTIONS, "optimise"}
    if unknown:
        raise RigError(
            f"config {path}: unknown section(s) {', '.join(sorted(unknown))}",
            f"use {', '.join((*FRONT_SECTIONS, 'optimise'))}",
        )
    # Checked now, not when the stage is reached minutes later.
    front = {k: v for k, v in data.items() if k in FRONT_SECTIONS}
    FrontConfig.from_mapping(front, f"config {path}")
    OptimiseSettings.from_mapping(data.get("optimise"), f"config {path}")
    return data


def session_spectra(session: Session, names: list[str]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Camera sensitivity and the SPD of each illumination from the session's calibration
    snapshot (entries named in ``session.yaml`` → ``calibration``)."""
    cal = session.info.calibration
    if not session.calibration_dir.is_dir() or cal.camera is None:
        raise RigError(
            f"{session.root} has no calibration snapshot (calibration/ and session.yaml "
            "calibration.camera)",
            "capture with a profile that names a calibration store",
        )
    store = CalibrationStore(session.calibration_dir)
    camera = store.camera(cal.camera, DEFAULT_GRID)
    spds = {}
    for name in names:
        entry = cal.lights.get(name, name)
        if entry not in store.names("light"):
            raise RigError(
                f"illumination {name!r} has no SPD in {session.calibration_dir} (entry {entry!r})",
                "measure it with `rig calibrate wizard` (or add it with `rig calibrate import "
                "SPD.txt --kind light --name NAME`) or name its store entry in the profile",
            )
        spds[name] = store.light_spd(entry, DEFAULT_GRID)
    return camera, spds


def flat_field_report(session: Session) -> dict[str, Any] | str:
    """The report's ``flat_field``: the lens fall-off correction decode applied, or none."""
    choice = session.info.calibration.flat_field
    if choice is None:
        return "none: frames not corrected for lens fall-off"
    return {"entry": choice.entry, "version": choice.version, "method": choice.method}


def _scaled(intr: Intrinsics, width: int, height: int) -> Intrinsics:
    """Intrinsics of another image size (SfM may run on downscaled images)."""
    if (intr.width, intr.height) == (width, height):
        return intr
    s = width / intr.width
    if abs(height / intr.height - s) > 1e-3:
        raise RigError(
            f"decoded frames are {width}x{height} but the camera is {intr.width}x{intr.height}",
            "re-run the poses stage on the decoded frames",
        )
    names = {"f", "fx", "fy", "cx", "cy"}
    from reconstruct.model.camera import CAMERA_MODELS

    params = tuple(
        p * s if n in names else p
        for n, p in zip(CAMERA_MODELS[intr.model], intr.params, strict=True)
    )
    return Intrinsics(intr.model, width, height, params)


def lit_frame(front: FrontResult, key: tuple[int, str]) -> tuple[np.ndarray, np.ndarray, float]:
    """A lit frame (image, saturation mask, noise weight) at the optimiser's level, with the
    view's ambient frame subtracted when the session has one
    (:mod:`reconstruct.frames.ambient`)."""
    img, sat, weight = _lit_decoded(front, key)
    steps = front.levels.optimise_step
    return downsample(img, steps), downsample_mask(sat, steps), weight


def _lit_decoded(
    front: FrontResult, key: tuple[int, str]
) -> tuple[np.ndarray, np.ndarray, float]:
    frame = front.frames[key]
    img, sat = load_frame(front.decoded_dir, frame)
    amb = front.frames.get((key[0], AMBIENT))
    if amb is None:
        return img, sat, 1.0
    amb_img, amb_sat = load_frame(front.decoded_dir, amb)
    if amb_img.shape != img.shape:
        raise RigError(
            f"ambient frame {amb.image} is {amb_img.shape[1]}x{amb_img.shape[0]} but lit frame "
            f"{frame.image} is {img.shape[1]}x{img.shape[0]}",
            "capture the ambient frame with the same camera and image size",
        )
    ratio = exposure_ratio(frame.exposure_s, frame.iso, amb.exposure_s, amb.iso)
    out = subtract_ambient(img, ~sat, amb_img, ~amb_sat, ratio, f"view {key[0]} {key[1]}")
    return out.image, ~out.valid, out.weight


def session_responses(session: Session) -> np.ndarray:
    """Response matrices (K, 3, N_λ) of the session's planned illuminations, in plan order
    sorted by name (as the optimiser stacks them)."""
    names = sorted(session.info.plan.illuminations or [])
    camera, spds = session_spectra(session, names)
    return response_matrices(camera, [spds[n] for n in names])


def optimiser_input(front: FrontResult, session: Session, basis: SpectralBasis) -> OptimiseInput:
    """Arrays the optimiser needs from the front's outputs and the calibration snapshot."""
    views = sorted(front.poses)
    column = {v: k for k, v in enumerate(views)}
    plan = session.info.plan.illuminations
    lit = None if plan is None else set(plan)  # ambient / pattern frames are not lit
    keys = sorted(k for k in front.frames if k[0] in column and (lit is None or k[1] in lit))
    if not keys:
        raise RigError(
            "no decoded frame under a named illumination belongs to a posed view",
            "check the poses stage output and the session's plan.illuminations",
        )
    names = sorted({k[1] for k in keys})
    camera, spds = session_spectra(session, names)
    responses = response_matrices(camera, [spds[n] for n in names])
    # Filled in place (stacking a list would hold the frames three times over), in float16 as
    # the decode cache keeps them: half the solve's largest array; samples are float64.
    first = lit_frame(front, keys[0])
    h, w = first[0].shape[:2]
    images = np.empty((len(keys), h, w, 3), dtype=np.float16)
    valid = np.empty((len(keys), h, w), dtype=bool)
    weight = np.empty(len(keys))
    for f, key in enumerate(keys):
        img, sat, weight[f] = first if f == 0 else lit_frame(front, key)
        if img.shape[:2] != (h, w):
            raise RigError(
                f"frame view {key[0]} {key[1]} is {img.shape[1]}x{img.shape[0]} but view "
                f"{keys[0][0]} {keys[0][1]} is {w}x{h}",
                "capture every frame of a session with the same camera and image size",
            )
        if images.dtype == np.float16 and float(np.max(img, initial=0.0)) >= FLOAT16_RANGE:
            images = images.astype(np.float32)  # exposure normalisation went past float16
        images[f] = img
        valid[f] = ~sat
    frames = Frames(
        np.array([column[k[0]] for k in keys]),
        np.array([names.index(k[1]) for k in keys]),
        images,
        valid,
        weight,
    )
    intr = [_scaled(front.intrinsics[v], w, h) for v in views]
    rig = Rig(intr, [front.poses[v] for v in views], responses)
    mesh = front.mesh
    return OptimiseInput(
        vertices=np.asarray(mesh.vertices, dtype=float),
        faces=np.asarray(mesh.faces, dtype=np.int64),
        visibility=front.visibility.matrix(views),
        rig=rig,
        frames=frames,
        basis=basis,
        # without a metric scale the light's distance, and with it the reflectance's scale, is
        # known only up to a factor: only the lower bound is physical
        reflectance_upper=1.0 if front.scale_is_metric else np.inf,
        # the bulb's size is in metres: without a metric scale it cannot be placed in the scene
        light_radius=session.info.light_diameter_m / 2 if front.scale_is_metric else 0.0,
    )


def export_result(
    recon_dir: Path,
    inp: OptimiseInput,
    result: OptimiseResult,
    settings: OptimiseSettings,
    extra: dict[str, Any],
    preview_views: int = 3,
) -> tuple[list[Path], dict[str, Any], Path, Path, Path]:
    """Write mesh.ply, reflectance.npz, the plots and last report.json, with this export's
    seconds (and, when ``extra`` has ``peak_rss_mb``, its peak memory) in it."""
    started = time.perf_counter()
    recon_dir.mkdir(parents=True, exist_ok=True)
    wl = inp.basis.wavelengths_nm
    normals, _ = vertex_normals(result.vertices, result.faces)
    unc = result.uncertainty
    std = None if unc is None else unc.reflectance_std
    band = None if unc is None else (unc.reflectance_low, unc.reflectance_high)
    arrays = (
        {}
        if unc is None
        else {
            "reflectance_std": unc.reflectance_std,
            "reflectance_low": unc.reflectance_low,
            "reflectance_high": unc.reflectance_high,
            "position_std_m": unc.position_std_m,
        }
    )
    # the 2-D estimate the joint solve started from, for viewers comparing the two
    arrays["initial_reflectance"] = inp.basis.reconstruct(result.initial_alpha)
    if result.colour_source is not None:
        arrays["colour_source"] = result.colour_source
    ply_extra = (
        {}
        if unc is None
        else {
            **{f"refl_std_{round(w)}": unc.reflectance_std[:, k] for k, w in enumerate(wl)},
            "position_std_m": unc.position_std_m,
        }
    )
    mesh_path = export.write_ply(
        recon_dir / export.MESH_FILE,
        result.vertices,
        result.faces,
        normals,
        result.reflectance,
        wl,
        ply_extra,
    )
    npz = export.write_reflectance_npz(
        recon_dir / export.REFLECTANCE_FILE,
        result.vertices,
        result.faces,
        normals,
        wl,
        result.reflectance,
        result.alpha,
        inp.basis.B,
        result.observed,
        arrays,
    )
    rig = inp.rig
    figures = [
        plots.cameras_and_lights(
            recon_dir / "cameras_lights.png", rig.poses, result.light_positions, result.vertices
        ),
        plots.cost_curve(recon_dir / "cost.png", result.history),
    ]
    rng = np.random.default_rng(0)
    seen = np.flatnonzero(result.observed)
    sample = np.sort(rng.choice(seen, size=min(6, seen.size), replace=False)) if seen.size else seen
    figures.append(
        plots.spectra(
            recon_dir / "spectra.png",
            wl,
            result.reflectance,
            sample,
            initial=inp.basis.reconstruct(result.initial_alpha),
            band=band,
        )
    )
    if std is not None:
        figures.append(
            plots.error_histogram(
                recon_dir / "uncertainty.png",
                np.mean(std, axis=1),  # NaN rows (unobserved) are left out
                "per-vertex reflectance std (mean over wavelengths)",
            )
        )
    caster = RayCaster(result.vertices, result.faces)
    for c in np.linspace(0, rig.n_views - 1, min(preview_views, rig.n_views)).astype(int):
        img = relight(
            result.vertices,
            result.faces,
            result.reflectance,
            wl,
            Camera(rig.intrinsics[c], rig.poses[c]),
            result.light_positions[c],
            "D65",
            caster=caster,
        )
        figures.append(
            plots.image(
                recon_dir / f"preview_view{c:03d}.png",
                encode_srgb(img),
                f"view {c}: estimated reflectance under D65 at the estimated light",
            )
        )
    offset = result.light[0] if settings.light_mode == "offset" else None
    report = {
        "light": {
            "mode": settings.light_mode,
            "offset_m": None if offset is None else offset.tolist(),
            "positions_m": result.light_positions.tolist(),
        },
        "vertices": len(result.vertices),
        "faces": len(result.faces),
        "observed_vertices": int(result.observed.sum()),
        "observations": result.n_observations,
        "colour_from_neighbours": result.colour_from_neighbours,
        "uncertainty": None if unc is None else unc.summary(),
        "history": result.history,
        "timings_s": {**extra.pop("timings_s", {}), **result.stage_seconds},
        "settings": asdict(settings),
        **extra,
    }
    report["timings_s"]["export"] = time.perf_counter() - started
    if "peak_rss_mb" in report:
        report["peak_rss_mb"]["export"] = round(peak_rss_mb(), 1)
    report_path = export.write_report(recon_dir / export.REPORT_FILE, report)
    return figures, report, mesh_path, npz, report_path


def intermediates(recon_dir: Path, keep: bool) -> dict[str, Any]:
    """Megabytes in each stage folder, their total, and what is left once the decoded frames
    are deleted after the export (unless ``keep``)."""
    sizes = stage_sizes_mb(recon_dir)
    total = round(sum(sizes.values()), 1)
    frames = 0.0 if keep else round(frame_bytes(recon_dir / "decoded") / 1e6, 1)
    return {"stages": sizes, "total": total, "decoded_frames_deleted": frames,
            "left": round(total - frames, 1)}


def resolution_report(front: FrontResult, inp: OptimiseInput) -> dict[str, Any]:
    """The report's ``resolution``: the preset, each stage's pyramid level (0: the RAW
    frame) and image size, and the mesh's target edge (pixels of the decoded frames, and
    millimetres when the poses are metric)."""
    levels = front.levels
    frame = next(iter(front.frames.values()))
    summary = json.loads((front.mesh_path.parent / "subdivide.json").read_text())
    metric = front.scale_is_metric
    sampled = inp.rig.intrinsics[0]
    return {
        "detail": levels.detail,
        "levels": {"decode": levels.decode, "patchmatch": levels.patchmatch,
                   "optimise": levels.optimise},
        "sizes": {"decode": [frame.width, frame.height],
                  "patchmatch": list(level_size(frame.width, frame.height,
                                                levels.patchmatch - levels.decode)),
                  "optimise": [sampled.width, sampled.height]},
        "edge_px": levels.edge_px,
        "edge_mm": summary["target_edge"] * 1e3 if metric else None,
        "mm_per_px": levels.mm_per_px,
    }


# Below this ratio of the farthest to the nearest camera distance the light's distance on the
# camera plate trades against the reflectance scale (all views see the same inverse-square
# falloff; docs/usage-reconstruct.md).
MIN_DISTANCE_RATIO = 1.3


def camera_distances(inp: OptimiseInput) -> dict[str, float]:
    """Camera-to-object distances (to the mesh centroid): how well the capture pins down the
    light's distance apart from the reflectance scale."""
    centre = np.mean(inp.vertices, axis=0)
    d = np.array([np.linalg.norm(pose.center - centre) for pose in inp.rig.poses])
    return {
        "min": float(d.min()),
        "median": float(np.median(d)),
        "max": float(d.max()),
        "ratio": float(d.max() / max(d.min(), 1e-12)),
    }


def warn_if_light_distance_weak(distances: dict[str, float], light_mode: str) -> None:
    """Tell the user, before the long solve, when every view is at about the same distance."""
    if light_mode != "offset" or distances["ratio"] >= MIN_DISTANCE_RATIO:
        return
    log.warning(
        "all views are %.2f-%.2f m from the object (ratio %.2f < %.1f): the light's distance on "
        "the camera plate is weakly observable and may end centimetres off along the optical "
        "axis; capture some views closer and some farther (e.g. 0.7x and 1.3x the usual "
        "distance) next time",
        distances["min"],
        distances["max"],
        distances["ratio"],
        MIN_DISTANCE_RATIO,
    )


def warn_if_solve_exceeds_memory(inp: OptimiseInput, settings: OptimiseSettings) -> None:
    """Tell the user, before the long solve, when it will likely need more memory than the
    machine has left: the system would otherwise stop it without a word, minutes in."""
    per_view = np.count_nonzero(inp.visibility, axis=0)
    pairs = int(per_view[inp.frames.view].sum())
    held = sum(a.nbytes for a in (inp.frames.images, inp.frames.valid) if a is not None)
    if settings.coarse_blur_px > 0 and inp.frames.images is not None:
        held *= 2  # the coarse stages sample a blurred copy of the frames beside them
    need, have = solve_memory_gb(pairs, held), memory_within_reach_gb()
    if need <= have:
        return
    log.warning(
        "the joint solve needs about %.1f GB (%d vertices, %d vertex-frame pairs) and this "
        "machine has %.1f GB left: it may be stopped for lack of memory; a coarser --detail "
        "(or a larger --edge-mm: twice the edge, a quarter of the pairs) keeps it smaller",
        need,
        len(inp.vertices),
        pairs,
        have,
    )


def projector_lights(
    front: FrontResult, settings: OptimiseSettings, explicit_mode: bool
) -> np.ndarray | None:
    """The initial light positions on projector sessions (None otherwise); without an explicit
    ``optimise.light_mode`` the settings switch to ``fixed`` lights at those positions."""
    if front.light_mode_hint != "free" or front.initial_light_positions is None:
        return None
    if not explicit_mode:
        settings.light_mode = "fixed"
    if settings.light_mode == "offset":
        return None
    return np.asarray(front.initial_light_positions, dtype=float)


def run_reconstruction(
    session: Session | Path,
    config: Mapping[str, Any] | None = None,
    initial_mesh: Path | None = None,
    progress: Progress | None = None,
    basis: SpectralBasis | None = None,
    keep_intermediates: bool = True,
) -> Reconstruction:
    """Both halves of the pipeline on a session (opened by the caller, or its folder; opened
    once either way); outputs in ``SESSION/recon/``. The session is locked (core.lock) for
    the whole run. Without ``keep_intermediates`` the decoded frames are deleted after a
    successful export (a later run decodes them again)."""
    conf = dict(config or {})
    opt_conf = conf.pop("optimise", None)
    settings = OptimiseSettings.from_mapping(opt_conf, "config optimise")
    session = Session.of(session)
    with (
        locked(session.root, RECONSTRUCT),
        tracked(session.recon_dir) as status,
        timed_run(session.recon_dir) as timings,
    ):
        rec = _run(session, conf, opt_conf, settings, initial_mesh, progress, basis, status,
                   timings, keep_intermediates)
        if rec.report["skipped_frames"]:
            status.end("complete", skipped_frames=len(rec.report["skipped_frames"]))
    return rec


def _run(
    session: Session,
    conf: dict[str, Any],
    opt_conf: Mapping[str, Any] | None,
    settings: OptimiseSettings,
    initial_mesh: Path | None,
    progress: Progress | None,
    basis: SpectralBasis | None,
    status: RunStatus,
    timings: Timings,
    keep_intermediates: bool,
) -> Reconstruction:
    t0 = time.perf_counter()
    status.stage("front")
    front = run_front(
        session, {k: v for k, v in conf.items() if k in FRONT_SECTIONS}, initial_mesh,
        glossy=settings.glossy,
    )
    t_front = time.perf_counter() - t0
    t0 = time.perf_counter()
    inp = optimiser_input(front, session, basis or default_basis())
    inp.initial_light = projector_lights(front, settings, "light_mode" in (opt_conf or {}))
    t_load = time.perf_counter() - t0
    distances = camera_distances(inp)
    warn_if_light_distance_weak(distances, settings.light_mode)
    warn_if_solve_exceeds_memory(inp, settings)
    recon = session.recon_dir
    t0 = time.perf_counter()
    status.stage("optimise")
    checkpoint = Checkpoint(recon / "optimise" / CHECKPOINT_FILE, input_key(inp, settings))
    reset_peak_rss()
    result = optimise(inp, settings, progress, checkpoint)
    # None for a front stage this run skipped (done before)
    peaks = {**timings.peaks(leave_out=("optimise", "export")), "optimise": round(peak_rss_mb(), 1)}
    timings.record("optimise", time.perf_counter() - t0, False, peaks["optimise"])
    reset_peak_rss()
    absolute = front.scale_is_metric
    extra = {
        "reflectance_scale_absolute": bool(absolute),
        "reflectance_scale_note": (
            "absolute: metric poses and radiometrically scaled calibration SPDs"
            if absolute
            else "relative: poses have no metric scale, so the light distance and the "
            "reflectance scale are only known up to a common factor"
        ),
        "poses": {"source": front.pose_summary.source, "scale": front.pose_summary.scale},
        "camera_distance_m": distances,
        "initial_mesh": str(front.mesh_path),
        "illuminations": sorted({k[1] for k in front.frames}),
        "skipped_frames": dict(front.skipped_frames),
        "flat_field": flat_field_report(session),
        "timings_s": {"front": t_front, "load_frames": t_load},
        "peak_rss_mb": peaks,
        "intermediates_mb": intermediates(recon, keep_intermediates),
        "resolution": resolution_report(front, inp),
    }
    status.stage("export")
    staging = staging_dir(recon)
    figures, report, mesh_path, npz, report_path = export_result(
        staging, inp, result, settings, extra
    )
    publish(recon, staging)
    if not keep_intermediates:
        freed = drop_frames(front.decoded_dir)
        log.info("deleted the decoded frames (%.1f MB); a later run decodes them again",
                 freed / 1e6)
    timings.record(
        "export", report["timings_s"]["export"], False, report["peak_rss_mb"]["export"]
    )
    mesh_path, npz, report_path = (recon / p.name for p in (mesh_path, npz, report_path))
    figures = [recon / p.name for p in figures]
    return Reconstruction(recon, mesh_path, npz, report_path, figures, result, report)
