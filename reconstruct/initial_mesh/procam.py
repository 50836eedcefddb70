"""Projector rigs (paper Sec. 4.2, after Pro-Cam SSfM): Gray code -> dense initial mesh.

Two ways to turn decoded projector coordinates into 3-D points, chosen per session:

* ``placements`` (no projector calibration): the projector stays put while the camera takes
  several views, then moves (camera and projector moved alternately). Camera pixels of views
  lit from the same placement that decode to the same projector block see the same surface
  spot; their centroids are matched and triangulated with the camera poses. The projector's
  pose per placement is then recovered by resection (PnP) from those points, and its optical
  centre is that placement's light position.
* ``plate``: the projector rides on the camera plate at the profile's ``light_mount.offset_m``
  with the camera's orientation, so every view is its own placement and the projector is a
  second, known "camera": camera pixel and projector block are triangulated directly
  (needs the projector's focal length, e.g. throw ratio x width).

Manifest frames name their placement in ``projector_placement`` (any JSON value); without it
``auto`` picks ``plate``. Points go through a vectorised multi-view DLT, are rejected by
reprojection error, triangulation angle and cheirality, get PCA normals facing the cameras,
and are meshed by screened Poisson (``pycolmap.poisson_meshing``, CPU), trimmed to the cloud.
The geometry lives beside this stage: :mod:`~reconstruct.initial_mesh.triangulation`,
:mod:`~reconstruct.initial_mesh.projector_pose`, :mod:`~reconstruct.initial_mesh.point_cloud`.

Outputs in ``out_dir``: ``initial.ply``, ``points.ply`` (oriented cloud), ``lights.json``
(per-view projector light position, for the optimiser's free-light mode), ``procam.json``
(counts, residuals, projector poses) and ``decoding/view_NNNN.npz``.
"""

from __future__ import annotations

import json
import logging
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path
from typing import Any, Literal

import numpy as np
from rich.progress import track

from core.config import bounded, from_mapping
from core.errors import RigError
from core.files import write_bytes_atomically
from core.labels import REFERENCES, is_structured
from core.manifest import FrameRecord
from core.session import Session
from reconstruct.frames.decode import INDEX, LINEAR_SUFFIXES, DecodeIndex, decode_linear, decode_raw
from reconstruct.frames.decode import load_frame as load_decoded
from reconstruct.initial_mesh.dense.poisson import poisson_mesh, write_oriented_ply
from reconstruct.initial_mesh.point_cloud import (
    drop_outliers,
    keep_large_pieces,
    oriented_normals,
    trim_to_cloud,
)
from reconstruct.initial_mesh.projector_pose import light_positions, projector_pose
from reconstruct.initial_mesh.repair import RepairConfig, repair
from reconstruct.initial_mesh.structured_light import DecodeOptions, GrayDecoding, decode_gray
from reconstruct.initial_mesh.triangulation import (
    Observer,
    block_centroids,
    check_points,
    match_blocks,
    triangulate,
)
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.poses.sfm import rescale
from reconstruct.stages.resumable import run_stage

log = logging.getLogger("reconstruct.initial_mesh.procam")

MESH = "initial.ply"
POINTS = "points.ply"
LIGHTS = "lights.json"
SUMMARY = "procam.json"
PLACEMENT_KEY = "projector_placement"
@dataclass(frozen=True)
class ProcamConfig:
    """``mode``: auto | placements | plate; ``projector_focal_px``: the projector's focal length
    in pixels (plate mode needs it; placements mode estimates it when absent);
    ``projector_size``: (width, height), default from the session's device description;
    ``max_reproj_px`` / ``min_angle_deg``: triangulation rejection; ``poisson_depth``,
    ``poisson_trim``: Poisson octree depth and density trim; ``trim_distance``: mesh faces
    farther than this many point spacings from the cloud are cut."""

    mode: Literal["auto", "placements", "plate"] = "auto"
    projector_focal_px: float | None = bounded(None, above=0.0, max=1e6)
    projector_size: tuple[int, int] | None = bounded(None, min=1, max=32_768)
    min_contrast: float = bounded(0.05, min=0.0, max=1.0)
    min_bit_contrast: float = bounded(0.25, min=0.0, max=1.0)
    auto_bits: bool = True
    min_views: int = bounded(2, min=2, max=1000)
    max_reproj_px: float = bounded(2.0, above=0.0, max=1000.0)
    min_angle_deg: float = bounded(2.0, min=0.0, max=90.0)
    normal_neighbours: int = bounded(12, min=3, max=1000)
    poisson_depth: int = bounded(8, min=1, max=14)
    poisson_trim: float = bounded(5.0, min=0.0, max=1000.0)
    trim_distance: float = bounded(4.0, above=0.0, max=1e6)
    num_threads: int = bounded(1, min=1, max=1024)

    @property
    def decode_options(self) -> DecodeOptions:
        return DecodeOptions(self.min_contrast, self.min_bit_contrast, self.auto_bits)


# --- frames -------------------------------------------------------------------------------


class FrameSource:
    """Linear frames of a session: the decode stage's output when present, else the files."""

    def __init__(self, session: Session, decoded_dir: Path | None) -> None:
        self.session = session
        self.decoded: dict[tuple[int, str], Any] = {}
        self.decoded_dir = decoded_dir
        if decoded_dir is not None and (decoded_dir / INDEX).is_file():
            for f in DecodeIndex.load(decoded_dir).frames:
                self.decoded[f.view, f.illumination] = f
        self.records: dict[tuple[int, str], FrameRecord] = {
            (r.view, r.illumination): r for r in session.frames
        }

    def labels(self, view: int) -> list[str]:
        return [lab for (v, lab) in self.records if v == view and is_structured(lab)]

    def load(self, view: int, label: str) -> tuple[np.ndarray, np.ndarray | None]:
        if (view, label) in self.decoded and self.decoded_dir is not None:
            return load_decoded(self.decoded_dir, self.decoded[view, label])
        record = self.records[view, label]
        path = self.session.root / record.path
        try:
            if path.suffix.lower() in LINEAR_SUFFIXES:
                return decode_linear(path, record, 0.98)
            return decode_raw(path, "linear", 0.98)
        except Exception as exc:  # rawpy, tifffile and numpy raise many types
            raise RigError(
                f"frame {record.path} (view {view}, {label}) cannot be read: {exc}",
                "run `rig session verify` and recapture the view with `rig capture --resume`",
            ) from exc


def has_gray_code(session: Session) -> bool:
    """Whether a session carries structured-light frames (it then takes the projector path,
    and those frames are not illuminations for the optimiser)."""
    return any(is_structured(r.illumination) and r.illumination not in REFERENCES
               for r in session.frames)


def projector_size(session: Session, conf: ProcamConfig) -> tuple[int, int] | None:
    """The projector's (width, height): configuration, else the session's plan or device
    record (``session.yaml``)."""
    if conf.projector_size is not None:
        return (int(conf.projector_size[0]), int(conf.projector_size[1]))
    return session.info.projector_size


def placements(session: Session, conf: ProcamConfig, views: list[int]) -> dict[int, Any]:
    """View -> projector placement: the manifest's ``projector_placement`` or, in plate mode,
    the view itself."""
    recorded: dict[int, Any] = {}
    for r in session.frames:
        if r.view in views and PLACEMENT_KEY in r.extra:
            recorded[r.view] = json.dumps(r.extra[PLACEMENT_KEY])
    mode = conf.mode
    if mode == "auto":
        mode = "placements" if recorded else "plate"
    if mode == "plate":
        return {v: None for v in views}
    missing = [v for v in views if v not in recorded]
    if missing:
        raise RigError(
            f"views {missing} of {session.root} name no {PLACEMENT_KEY} in the manifest",
            "record the projector placement of every view, or set procam.mode: plate",
        )
    return recorded


def read_light_positions(out_dir: Path) -> dict[int, np.ndarray]:
    """``lights.json`` written by :func:`procam_initial_mesh` -> view -> position."""
    data = json.loads((Path(out_dir) / LIGHTS).read_text())
    return {int(v): np.asarray(p, dtype=float) for v, p in data["positions"].items()}


# --- the stage ----------------------------------------------------------------------------


@dataclass
class _Cloud:
    points: list[np.ndarray]
    towards: list[np.ndarray]
    residuals: list[np.ndarray]


def _decode_views(
    source: FrameSource, views: list[int], size: tuple[int, int] | None, conf: ProcamConfig,
    out_dir: Path,
) -> dict[int, GrayDecoding]:
    (out_dir / "decoding").mkdir(exist_ok=True)
    decoded: dict[int, GrayDecoding] = {}
    for view in track(views, description="decoding Gray code"):
        labels = source.labels(view)
        if not labels:
            continue
        dec = decode_gray(labels, partial(source.load, view), size, conf.decode_options)
        np.savez_compressed(
            out_dir / "decoding" / f"view_{view:04d}.npz", col=dec.col, row=dec.row,
            valid=dec.valid, steps=[dec.col_step, dec.row_step],
        )
        log.info("view %d: %d pixels decoded (blocks of %dx%d projector pixels), rejected %s",
                 view, int(dec.valid.sum()), dec.col_step, dec.row_step, dec.rejected)
        decoded[view] = dec
    return decoded


def _intrinsics_for(view: int, intrinsics: Intrinsics | Mapping[int, Intrinsics],
                    shape: tuple[int, int]) -> Intrinsics:
    intr = intrinsics if isinstance(intrinsics, Intrinsics) else intrinsics[view]
    h, w = shape
    return intr if (intr.width, intr.height) == (w, h) else rescale(intr, w, h)


def _triangulate_group(
    views: list[int], decoded: dict[int, GrayDecoding], poses: Mapping[int, Pose],
    intrinsics: Intrinsics | Mapping[int, Intrinsics], projector: Observer | None,
    conf: ProcamConfig,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points, their directions to the cameras, RMS residuals, projector pixels and a mask of
    the points that passed, for the views lit by one projector placement."""
    step = (max(decoded[v].col_step for v in views), max(decoded[v].row_step for v in views))
    per_view = [
        block_centroids(decoded[v], (step[0] // decoded[v].col_step,
                                     step[1] // decoded[v].row_step))
        for v in views
    ]
    keys, obs = match_blocks(per_view)
    observers = [
        Observer(_intrinsics_for(v, intrinsics, decoded[v].valid.shape), poses[v],
                 conf.max_reproj_px)
        for v in views
    ]
    n_rows = -(-decoded[views[0]].blocks[1] // (step[1] // decoded[views[0]].row_step))
    proj_xy = np.stack([(keys // n_rows + 0.5) * step[0], (keys % n_rows + 0.5) * step[1]], 1)
    need = conf.min_views
    if projector is not None:  # plate: the projector is a calibrated second view
        observers.append(Observer(projector.intrinsics, projector.pose,
                                  conf.max_reproj_px * max(step)))
        obs = np.concatenate([obs, proj_xy[:, None]], axis=1)
        need = 2
    enough = np.sum(~np.isnan(obs[:, :, 0]), axis=1) >= need
    obs, proj_xy = obs[enough], proj_xy[enough]
    points = triangulate(obs, observers)
    ok, rms = check_points(points, obs, observers, conf.min_angle_deg)
    towards = np.zeros_like(points)
    for k, v in enumerate(views):
        seen = ~np.isnan(obs[:, k, 0])
        d = poses[v].center - points[seen]
        towards[seen] += d / np.linalg.norm(d, axis=1, keepdims=True)
    return points, towards, rms, proj_xy, ok


def _procam(
    session: Session, poses: Mapping[int, Pose], intrinsics: Intrinsics | Mapping[int, Intrinsics],
    conf: ProcamConfig, out_dir: Path, decoded_dir: Path | None,
) -> None:
    source = FrameSource(session, decoded_dir)
    views = [v for v in session.views() if v in poses and source.labels(v)]
    unposed = [v for v in session.views() if v not in poses and source.labels(v)]
    if unposed:
        log.warning("views %s have Gray-code frames but no pose, not used", unposed)
    if not views:
        raise RigError(
            f"{session.root} has no Gray-code frames in views with a pose",
            "capture with a projector profile whose plan has structured_light.gray_code: true",
        )
    size = projector_size(session, conf)
    view_placement = placements(session, conf, views)
    plate = all(p is None for p in view_placement.values())
    offset = np.asarray(session.info.light_offset_m or (0.0, 0.0, 0.0), dtype=float)
    if plate and not offset.any():
        raise RigError(
            f"{session.root / 'session.yaml'} gives no light_mount.offset_m for the projector "
            "on the camera plate (camera and projector would share one centre)",
            "set light_mount.offset_m (projector lens relative to the camera lens, metres) in "
            "the profile, or record projector_placement per view",
        )
    if plate and conf.projector_focal_px is None:
        raise RigError(
            "a projector on the camera plate needs its focal length (procam.projector_focal_px)",
            "set it to throw ratio x projector width in pixels, or record projector_placement "
            "per view and move camera and projector alternately",
        )
    decoded = _decode_views(source, views, size, conf, out_dir)
    groups: dict[Any, list[int]] = defaultdict(list)
    for v in decoded:
        groups[view_placement[v] if not plate else v].append(v)
    cloud = _Cloud([], [], [])
    placement_poses: dict[Any, Pose] = {}
    info_placements: dict[str, Any] = {}
    for key, group in groups.items():
        projector = None
        psize = size or decoded[group[0]].projector_size
        if plate:
            assert conf.projector_focal_px is not None
            pose = poses[group[0]]
            projector = Observer(Intrinsics.pinhole(psize[0], psize[1], conf.projector_focal_px),
                                 Pose(pose.R, pose.t - offset), conf.max_reproj_px)
            placement_poses[key] = projector.pose
        elif len(group) < conf.min_views:
            log.warning("placement %s lights only view(s) %s, needs %d views: not used", key,
                        group, conf.min_views)
            continue
        pts, towards, rms, proj_xy, ok = _triangulate_group(
            group, decoded, poses, intrinsics, projector, conf)
        log.info("placement %s (views %s): %d of %d matches triangulated", key, group,
                 int(ok.sum()), len(ok))
        entry: dict[str, Any] = {"views": group, "matches": len(ok), "points": int(ok.sum()),
                                 "rms_px": float(np.median(rms[ok])) if ok.any() else None}
        if not plate and ok.any():
            step = max(max(decoded[v].col_step, decoded[v].row_step) for v in group)
            try:
                intr, ppose, inl = projector_pose(pts[ok], proj_xy[ok], psize,
                                                  conf.projector_focal_px,
                                                  conf.max_reproj_px * step)
            except RigError as exc:  # the mesh is still useful; the optimiser lacks a seed
                log.warning("placement %s: no projector pose (%s)", key, exc)
            else:
                placement_poses[key] = ppose
                entry |= {"projector_focal_px": float(intr.params[0]), "pnp_inliers": inl}
        if key in placement_poses:
            entry["projector_centre"] = [float(x) for x in placement_poses[key].center]
        info_placements[str(key)] = entry
        cloud.points.append(pts[ok])
        cloud.towards.append(towards[ok])
        cloud.residuals.append(rms[ok])
    if not cloud.points or sum(len(p) for p in cloud.points) < 100:
        raise RigError(
            f"too few 3-D points from the Gray code of {session.root} "
            f"({sum(len(p) for p in cloud.points)})",
            "check the camera poses, the projector focal length, and that views of one "
            "projector placement overlap",
        )
    points = np.concatenate(cloud.points)
    towards = np.concatenate(cloud.towards)
    keep = drop_outliers(points)
    points, towards = points[keep], towards[keep]
    normals = oriented_normals(points, towards, conf.normal_neighbours)
    write_oriented_ply(out_dir / POINTS, points, normals)
    mesh = poisson_mesh(points, normals, conf.poisson_depth, conf.poisson_trim,
                        conf.num_threads, largest_only=False, trim_option="procam.poisson_trim")
    mesh = (
        trim_to_cloud(mesh, points, conf.trim_distance)
        if conf.trim_distance > 0
        else keep_large_pieces(mesh, 0.05)
    )
    # the pieces are chosen above; the repair only orients, closes and re-meshes
    mesh, repaired = repair(mesh, RepairConfig(keep_fraction=0.0))
    mesh.export(out_dir / MESH)
    lights = light_positions(
        {v: (view_placement[v] if not plate else v) for v in decoded}, placement_poses
    )
    write_bytes_atomically(out_dir / LIGHTS, json.dumps({
        "mode": "plate" if plate else "placements",
        "positions": {str(v): [float(x) for x in p] for v, p in sorted(lights.items())},
    }, indent=1).encode())
    summary = {
        "method": "procam_gray_code+poisson", "mode": "plate" if plate else "placements",
        "points": len(points), "outliers_dropped": int((~keep).sum()),
        "median_rms_px": float(np.median(np.concatenate(cloud.residuals))),
        "vertices": len(mesh.vertices), "faces": len(mesh.faces),
        "placements": info_placements, "repair": repaired,
    }
    write_bytes_atomically(out_dir / SUMMARY, json.dumps(summary, indent=1).encode())
    log.info("procam initial mesh: %d points -> %d vertices", len(points), len(mesh.vertices))


def procam_initial_mesh(
    session: Session,
    poses: Mapping[int, Pose],
    intrinsics: Intrinsics | Mapping[int, Intrinsics],
    conf: ProcamConfig | Mapping[str, Any],
    out_dir: Path,
    decoded_dir: Path | None = None,
) -> Path:
    """Initial mesh of a projector session from its Gray-code frames (resumable stage).

    Frames come from the decode stage's ``decoded_dir`` when given (``recon/decoded``), else
    straight from the session's files. ``poses`` and ``intrinsics`` are per view (the poses
    stage's output). Returns ``out_dir/initial.ply``; ``lights.json`` beside it holds the
    projector light position of every view.
    """
    conf = from_mapping(ProcamConfig, conf, "config", "procam")
    out_dir = Path(out_dir)
    inputs = [session.root / "manifest.jsonl", session.root / "session.yaml"]
    if decoded_dir is not None:
        inputs.append(Path(decoded_dir) / INDEX)
    state = asdict(conf) | {
        "poses": {str(v): [p.R.tolist(), p.t.tolist()] for v, p in sorted(poses.items())},
        "intrinsics": str(intrinsics),
    }
    run_stage(
        "initial_mesh_procam", state, inputs, out_dir,
        lambda: _procam(session, poses, intrinsics, conf, out_dir, decoded_dir),
    )
    return out_dir / MESH
