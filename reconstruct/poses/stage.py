"""Poses stage: known poses from ``SESSION/poses/``, a printed ChArUco board under the object,
or incremental SfM with pycolmap (CPU); board and SfM merged when both are available.

Source (``poses.source``): ``auto`` takes known poses when ``SESSION/poses/images.txt``
exists, else the board when ``session.yaml`` (or its profile snapshot) has a ``board:`` entry,
else SfM. The board gives metric poses in its own frame (origin at the board centre, z up), so
meshes come out upright and in metres; SfM, run beside it by default, adds the views where the
board is hidden, carried into the board frame by a robust similarity. A failing SfM (a
texture-poor object) is tolerated when the board posed at least three views; a board that
posed too few views falls back to SfM in ``auto``.

Output in ``recon/poses/``: a COLMAP text model (image id = view + 1, image name
``view_NNNN.png``, intrinsics at the decoded frames' full resolution), ``poses.json`` (source,
registered/total views, mean reprojection error, whether the scale is metric or relative, and
per view its pose source and board-corner reprojection error) and ``points3D.npy`` (SfM
points in the output frame, for bounding the dense stage; empty without SfM).

Metric scale: known and board poses are in metres. SfM alone poses are scaled when the session's
``session.yaml`` (top level or its ``profile`` snapshot) names ``known_distances``: a list of
``{views: [a, b], metres: d}``, each the measured distance between the camera centres of two
views (a tape measure, a turntable radius, a slide rail); the median ratio is applied.
Without it the scale is relative and reflectance is known only up to one common factor.

Known poses match views by image name: a manifest frame's file path, its file name or stem,
``view_NNNN[.ext]``, or the view number itself.
"""

from __future__ import annotations

import json
import logging
import re
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import pycolmap

from core.config import bounded, from_mapping
from core.errors import RigError
from core.session import Session, write_bytes_atomically
from reconstruct.frames.decode import INDEX, SFM_DIR, DecodeIndex, load_frame
from reconstruct.model.camera import (
    CAMERA_MODELS,
    Intrinsics,
    Pose,
    read_colmap_text,
    write_colmap_text,
)
from reconstruct.poses.board import (
    BoardPoseResult,
    BoardSpec,
    MergedPoses,
    board_poses,
    corner_residuals,
    detect_board,
    linear_to_u8,
    merge_with_sfm,
)
from reconstruct.poses.board.poses import rms_of
from reconstruct.run.progress import track
from reconstruct.run.stages import quiet_colmap, run_stage

log = logging.getLogger("reconstruct.poses.stage")

SUMMARY = "poses.json"
POINTS = "points3D.npy"
MIN_VIEWS = 3


@dataclass(frozen=True)
class PosesConfig:
    """``source``: auto | known | board | sfm (see the module docstring); ``use_known``: let
    ``auto`` read ``SESSION/poses`` when present; ``matcher``: exhaustive, sequential or auto
    (exhaustive up to 60 views); ``max_features``: SIFT features per image;
    ``refine_intrinsics``: let bundle adjustment refine given intrinsics.

    Board: ``board_with_sfm`` also runs SfM and merges it in (``auto``: only when the board
    leaves a view unposed — SfM then adds nothing but minutes); ``board_min_corners`` /
    ``board_max_rms_px``: a view gets a board pose with at least this many corners and at most
    this RMS error; ``board_model``: camera model estimated from the board views when the
    profile gives no intrinsics; ``board_refine_intrinsics``: free given intrinsics in the
    board adjustment (None: only when estimated).

    The defaults suit the rig: a small object turning under a lamp that moves with the camera,
    so few, strongly changing features. Affine-covariant SIFT with domain-size pooling, guided
    matching and a 30-inlier initial pair register the simulated 40-view rings fully where
    COLMAP's photo defaults (upright DoG, 100 inliers) split them into fragments.
    """

    source: Literal["auto", "known", "board", "sfm"] = "auto"
    use_known: bool = True
    matcher: Literal["auto", "exhaustive", "sequential"] = "auto"
    max_features: int = bounded(8192, min=1, max=1_000_000)
    affine_sift: bool = True
    guided_matching: bool = True
    init_min_inliers: int = bounded(30, min=1, max=100_000)
    refine_intrinsics: bool = False
    num_threads: int = bounded(-1, min=-1, max=1024)  # -1: all cores
    board_with_sfm: bool | Literal["auto"] = "auto"
    board_min_corners: int = bounded(6, min=1, max=100_000)
    board_max_rms_px: float = bounded(3.0, above=0.0, max=1000.0)
    board_model: str = "RADIAL"
    board_refine_intrinsics: bool | None = None


@dataclass
class PoseSummary:
    source: str  # "known", "board", "board+sfm" or "sfm"
    registered: int
    total: int
    registered_views: list[int]
    unregistered_views: list[int]
    mean_reprojection_error_px: float | None
    scale: str  # "metric" or "relative"
    scale_factor: float
    intrinsics_source: str
    extra: dict[str, Any] = field(default_factory=dict)
    # view (as a string) -> {"source": ..., "reprojection_px": board-corner RMS or None, ...}
    views: dict[str, dict[str, Any]] = field(default_factory=dict)


@dataclass
class SfmResult:
    """Registered image name -> (intrinsics at the SfM image size, pose); sparse points."""

    cameras: dict[str, tuple[Intrinsics, Pose]]
    points: np.ndarray
    mean_reprojection_error_px: float


def session_value(info: Mapping[str, Any], *keys: str) -> Any:
    """A value at ``keys`` in session.yaml, else in its ``profile`` snapshot, else None."""
    for root in (info, info.get("profile") or {}):
        node: Any = root
        for key in keys:
            node = node.get(key) if isinstance(node, Mapping) else None
        if node is not None:
            return node
    return None


def session_intrinsics(info: Mapping[str, Any]) -> Intrinsics | None:
    """``intrinsics`` or ``camera.intrinsics`` as ``{model, width, height, params}``."""
    spec = session_value(info, "intrinsics") or session_value(info, "camera", "intrinsics")
    if spec is None:
        return None
    try:
        return Intrinsics(
            str(spec["model"]), int(spec["width"]), int(spec["height"]),
            tuple(float(p) for p in spec["params"]),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise RigError(
            f"session.yaml intrinsics are malformed ({exc})",
            "give intrinsics: {model: PINHOLE, width: W, height: H, params: [fx, fy, cx, cy]}",
        ) from exc


def rescale(intr: Intrinsics, width: int, height: int) -> Intrinsics:
    """The same camera at another image size (pixel edges scale, so do principal points)."""
    if (width, height) == (intr.width, intr.height):
        return intr
    sx, sy = width / intr.width, height / intr.height
    scaled = []
    for name, value in zip(CAMERA_MODELS[intr.model], intr.params, strict=True):
        if name in ("f", "fx", "cx"):
            value *= sx if name != "f" else (sx + sy) / 2
        elif name in ("fy", "cy"):
            value *= sy
        scaled.append(float(value))
    return Intrinsics(intr.model, width, height, tuple(scaled))


def run_sfm(
    image_dir: Path,
    names: Sequence[str],
    conf: PosesConfig,
    work_dir: Path,
    intrinsics: Intrinsics | None = None,
) -> SfmResult:
    """SIFT + matching + incremental mapping with pycolmap on CPU; the largest model wins.

    ``intrinsics`` (at the images' size) are used as a fixed shared camera when given.
    """
    with quiet_colmap():
        return _sfm(image_dir, names, conf, work_dir, intrinsics)


def _sfm(
    image_dir: Path,
    names: Sequence[str],
    conf: PosesConfig,
    work_dir: Path,
    intrinsics: Intrinsics | None,
) -> SfmResult:
    database = work_dir / "database.db"
    database.unlink(missing_ok=True)
    reader = pycolmap.ImageReaderOptions()
    if intrinsics is not None:
        reader.camera_model = intrinsics.model
        reader.camera_params = ",".join(repr(float(p)) for p in intrinsics.params)
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = conf.num_threads
    extraction.sift.max_num_features = conf.max_features
    extraction.sift.estimate_affine_shape = conf.affine_sift
    extraction.sift.domain_size_pooling = conf.affine_sift
    pycolmap.extract_features(
        database, image_dir, image_names=list(names), camera_mode=pycolmap.CameraMode.SINGLE,
        reader_options=reader, extraction_options=extraction, device=pycolmap.Device.cpu,
    )
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = conf.num_threads
    matching.guided_matching = conf.guided_matching
    matcher = conf.matcher if conf.matcher != "auto" else (
        "exhaustive" if len(names) <= 60 else "sequential"
    )
    if matcher == "exhaustive":
        pycolmap.match_exhaustive(database, matching_options=matching, device=pycolmap.Device.cpu)
    else:
        pycolmap.match_sequential(database, matching_options=matching, device=pycolmap.Device.cpu)
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = conf.num_threads
    options.min_model_size = MIN_VIEWS
    options.mapper.init_min_num_inliers = conf.init_min_inliers
    options.mapper.abs_pose_min_num_inliers = max(15, conf.init_min_inliers // 2)
    if intrinsics is not None and not conf.refine_intrinsics:
        options.ba_refine_focal_length = False
        options.ba_refine_principal_point = False
        options.ba_refine_extra_params = False
    models = pycolmap.incremental_mapping(database, image_dir, work_dir / "sparse", options)
    if not models:
        raise RigError(
            f"structure from motion registered no views of {image_dir}",
            "the views must overlap and show texture; capture more views or give known poses "
            "in SESSION/poses/",
        )
    rec = max(models.values(), key=lambda r: r.num_reg_images())
    cameras: dict[str, tuple[Intrinsics, Pose]] = {}
    for image in rec.images.values():
        if not image.has_pose:
            continue
        cam = image.camera
        rigid = image.cam_from_world()
        intr = Intrinsics(
            cam.model.name, int(cam.width), int(cam.height), tuple(float(p) for p in cam.params)
        )
        cameras[image.name] = (
            intr, Pose(np.asarray(rigid.rotation.matrix()), np.asarray(rigid.translation))
        )
    points = np.array([p.xyz for p in rec.points3D.values()], dtype=float).reshape(-1, 3)
    return SfmResult(cameras, points, float(rec.compute_mean_reprojection_error()))


def view_of_name(name: str, session: Session) -> int | None:
    """Which view a known-pose image name refers to (see the module docstring)."""
    for record in session.frames:
        p = Path(record.path)
        if name in (record.path, p.name, p.stem):
            return record.view
    match = re.fullmatch(r"(?:view_)?(\d+)(?:\.\w+)?", Path(name).name)
    if match and int(match.group(1)) in set(session.views()):
        return int(match.group(1))
    return None


def metric_scale(info: Mapping[str, Any], centres: Mapping[int, np.ndarray]) -> float | None:
    """Median of measured / reconstructed camera-centre distances, None without any."""
    entries = session_value(info, "known_distances")
    if not entries:
        return None
    ratios = []
    for entry in entries:
        try:
            a, b = (int(v) for v in entry["views"])
            metres = float(entry["metres"])
        except (KeyError, TypeError, ValueError) as exc:
            raise RigError(
                f"session.yaml known_distances entry {entry!r} is malformed",
                "write each as {views: [a, b], metres: d}",
            ) from exc
        if a in centres and b in centres:
            ratios.append(metres / float(np.linalg.norm(centres[a] - centres[b])))
        else:
            log.warning("known distance between views %d and %d: a view is not registered", a, b)
    return float(np.median(ratios)) if ratios else None


def session_board(info: Mapping[str, Any]) -> BoardSpec | None:
    """The ``board:`` entry of session.yaml (or its profile snapshot), None without one."""
    data = session_value(info, "board")
    return None if data is None else BoardSpec.from_dict(data, source="session.yaml")


def _known(
    session: Session, decoded: DecodeIndex
) -> tuple[dict[int, tuple[Intrinsics, Pose]], PoseSummary]:
    cams, images = read_colmap_text(session.poses_dir)
    out: dict[int, tuple[Intrinsics, Pose]] = {}
    for cid, name, pose in images.values():
        view = view_of_name(name, session)
        if view is None:
            log.warning("known pose %s matches no view of the session, ignored", name)
            continue
        if cid not in cams:
            raise RigError(
                f"{session.poses_dir / 'images.txt'}: image {name} uses camera {cid}, "
                "which cameras.txt lacks", "add the camera or fix the id",
            )
        out[view] = (cams[cid], pose)
    views = sorted(decoded.sfm_images)
    posed = sorted(set(out) & set(views))
    summary = PoseSummary(
        "known", len(posed), len(views), posed, sorted(set(views) - set(out)), None, "metric",
        1.0, "known poses", views={str(v): {"source": "known"} for v in posed},
    )
    return out, summary


def _full_size(decoded: DecodeIndex, view: int) -> tuple[int, int]:
    first = next(f for f in decoded.frames if f.view == view)
    return first.width, first.height


def _sfm_poses(
    session: Session,
    decoded: DecodeIndex,
    decoded_dir: Path,
    conf: PosesConfig,
    out_dir: Path,
    intrinsics: Intrinsics | None = None,
    only: Sequence[int] | None = None,
) -> tuple[dict[int, tuple[Intrinsics, Pose]], PoseSummary, np.ndarray]:
    """SfM poses (of the views ``only``, when given); ``intrinsics`` (full size) override the
    session's when given."""
    views = sorted(decoded.sfm_images if only is None else set(only) & set(decoded.sfm_images))
    full = _full_size(decoded, views[0])
    names = [decoded.sfm_images[v] for v in views]
    sfm_image = cv2.imread(str(decoded_dir / SFM_DIR / names[0]), cv2.IMREAD_UNCHANGED)
    if sfm_image is None:
        raise RigError(f"{decoded_dir / SFM_DIR / names[0]} cannot be read", "delete recon/decoded")
    h, w = sfm_image.shape[:2]
    given = intrinsics if intrinsics is not None else session_intrinsics(session.info)
    with tempfile.TemporaryDirectory(dir=out_dir) as tmp:
        result = run_sfm(
            decoded_dir / SFM_DIR, names, conf, Path(tmp),
            rescale(given, w, h) if given is not None else None,
        )
    by_name = {decoded.sfm_images[v]: v for v in views}
    out = {
        by_name[n]: (rescale(intr, *full), pose) for n, (intr, pose) in result.cameras.items()
    }
    scale = metric_scale(session.info, {v: p.center for v, (_, p) in out.items()})
    points = result.points
    if scale is not None:
        out = {v: (i, Pose(p.R, p.t * scale)) for v, (i, p) in out.items()}
        points = points * scale
    summary = PoseSummary(
        "sfm", len(out), len(views), sorted(out), sorted(set(views) - set(out)),
        result.mean_reprojection_error_px, "metric" if scale else "relative", scale or 1.0,
        "given" if intrinsics is not None else "session" if given is not None else "sfm",
        views={str(v): {"source": "sfm"} for v in sorted(out)},
    )
    return out, summary, points


def board_images(decoded: DecodeIndex, decoded_dir: Path) -> dict[int, np.ndarray]:
    """8-bit RGB image of each view at full resolution for corner detection: the SfM copy
    when it is full size (the view's brightest frame), else the brightest linear frame."""
    out: dict[int, np.ndarray] = {}
    for view, name in sorted(decoded.sfm_images.items()):
        width, height = _full_size(decoded, view)
        png = cv2.imread(str(decoded_dir / SFM_DIR / name), cv2.IMREAD_COLOR)
        if png is not None and png.shape[:2] == (height, width):
            out[view] = np.ascontiguousarray(png[:, :, ::-1])
            continue
        frames = [load_frame(decoded_dir, f)[0] for f in decoded.frames if f.view == view]
        out[view] = linear_to_u8(max(frames, key=lambda img: float(np.mean(img))))
    return out


def _board(
    session: Session, decoded: DecodeIndex, decoded_dir: Path, conf: PosesConfig, spec: BoardSpec
) -> BoardPoseResult[int]:
    images = board_images(decoded, decoded_dir)
    detections = {
        v: detect_board(img, spec)
        for v, img in track(list(images.items()), "finding the board")
    }
    size = _full_size(decoded, min(images))
    given = session_intrinsics(session.info)
    result = board_poses(
        detections, rescale(given, *size) if given is not None else None, size,
        min_corners=conf.board_min_corners, model=conf.board_model,
        refine_intrinsics=conf.board_refine_intrinsics, max_rms_px=conf.board_max_rms_px,
    )
    for view, why in sorted(result.rejected.items()):
        log.info("view %d: no board pose (%s)", view, why)
    log.info(
        "board: %d/%d views posed, RMS corner error %.3f px, intrinsics %s",
        len(result.poses), len(images), result.rms_px, result.intrinsics_source,
    )
    return result


def board_frame_check(
    decoded: DecodeIndex,
    decoded_dir: Path,
    spec: BoardSpec,
    cameras: Mapping[int, tuple[Intrinsics, Pose]],
    max_rms_px: float,
) -> tuple[bool, dict[int, float]]:
    """Whether given poses are in the board's frame (the board's corners reproject within
    ``max_rms_px``, median over the views that see at least 6), and each view's RMS."""
    errors: dict[int, float] = {}
    for view, image in board_images(decoded, decoded_dir).items():
        if view not in cameras:
            continue
        det = detect_board(image, spec)
        if det.n_corners >= 6:
            intr, pose = cameras[view]
            full = rescale(intr, image.shape[1], image.shape[0])
            errors[view] = rms_of(corner_residuals(full, pose, det))
    ok = len(errors) >= MIN_VIEWS and float(np.median(list(errors.values()))) <= max_rms_px
    return ok, errors


def _rounded(value: float) -> float | None:
    return None if not np.isfinite(value) else round(float(value), 4)


def _board_summary(
    board: BoardPoseResult[int],
    merged: MergedPoses[int] | None,
    views: list[int],
    sfm: PoseSummary | None,
    sfm_error: str | None,
) -> PoseSummary:
    """Per view: pose source, board-corner RMS error (of the final pose), corners seen, why the
    board gave no pose, and (shared views) how far the carried SfM pose is from the board's."""
    posed = merged.poses if merged is not None else board.poses
    sources = merged.source if merged is not None else dict.fromkeys(board.poses, "board")
    errors = merged.reprojection_px if merged is not None else board.reprojection_px
    per_view: dict[str, dict[str, Any]] = {}
    for view in views:
        entry: dict[str, Any] = {
            "source": sources.get(view, "none"),
            "reprojection_px": _rounded(errors.get(view, np.nan)),
            "board_corners": board.n_corners.get(view, 0),
        }
        if view in board.rejected:
            entry["board_rejected"] = board.rejected[view]
        if merged is not None and view in merged.alignment_residual_m:
            entry["alignment_residual_mm"] = round(1000 * merged.alignment_residual_m[view], 3)
            entry["alignment_rotation_deg"] = round(merged.alignment_rotation_deg[view], 4)
            entry["alignment_outlier"] = view in merged.alignment_outliers
        per_view[str(view)] = entry
    extra: dict[str, Any] = {"board_rms_px": _rounded(board.rms_px)}
    if merged is not None:
        extra["sfm_to_board"] = merged.summary()["sfm_to_board"]
    if sfm is not None:
        extra["sfm_registered"] = sfm.registered
        extra["sfm_mean_reprojection_error_px"] = sfm.mean_reprojection_error_px
    if sfm_error is not None:
        extra["sfm_error"] = sfm_error
    registered = sorted(set(posed) & set(views))
    return PoseSummary(
        "board+sfm" if merged is not None else "board", len(registered), len(views), registered,
        sorted(set(views) - set(posed)), _rounded(board.rms_px), "metric", 1.0,
        f"board ({board.intrinsics_source})", extra, per_view,
    )


SFM_NEIGHBOURS = 4  # views each side (capture order) SfM runs beside an unposed view


def sfm_neighbourhood(views: Sequence[int], unposed: Sequence[int], k: int) -> list[int]:
    """The views SfM needs to pose ``unposed`` into the board's frame: each with its ``k``
    neighbours on either side in capture order (cyclic: a ring's last view meets its first).
    Matching 10 views instead of 40 exhaustively took the poses stage of a 40-view 800×600
    session with two views hidden from the board from 156 s to 21 s (their centres 0.4–0.8 mm
    from the truth; 0.4–0.5 mm by SfM of every view)."""
    order = sorted(views)
    where = {v: i for i, v in enumerate(order)}
    picked = {
        order[(where[v] + d) % len(order)] for v in unposed for d in range(-k, k + 1)
    }
    return sorted(picked)


def _carries(
    sfm: Mapping[int, tuple[Intrinsics, Pose]], board: Mapping[int, Pose], unposed: Sequence[int]
) -> bool:
    """Whether an SfM model can carry the unposed views into the board frame: it poses them
    and shares at least :data:`MIN_VIEWS` views with the board."""
    return set(unposed) <= set(sfm) and len(set(sfm) & set(board)) >= MIN_VIEWS


def _sfm_beside_board(
    session: Session,
    decoded: DecodeIndex,
    decoded_dir: Path,
    conf: PosesConfig,
    out_dir: Path,
    board: BoardPoseResult[int],
    unposed: Sequence[int],
    neighbourhood: Sequence[int] | None,
) -> tuple[tuple[dict[int, tuple[Intrinsics, Pose]], PoseSummary, np.ndarray] | None, str | None]:
    """SfM with the board's intrinsics: of the unposed views' ``neighbourhood`` first when
    given, of every view when that cannot carry them into the board frame; (None, why) when
    SfM fails. A neighbourhood model's sparse points are dropped (they would bound the
    visual hull by one side of the object)."""
    if neighbourhood is not None:
        try:
            sfm = _sfm_poses(
                session, decoded, decoded_dir, conf, out_dir, board.intrinsics, neighbourhood
            )
            if _carries(sfm[0], board.poses, unposed):
                # its points cover only what those views see: no box for the visual hull
                return (sfm[0], sfm[1], np.zeros((0, 3))), None
            log.info("SfM of the unposed views' neighbours fell short; SfM of every view")
        except RigError as exc:
            log.info("SfM of the unposed views' neighbours failed (%s); SfM of every view",
                     exc.problem)
    try:
        return _sfm_poses(session, decoded, decoded_dir, conf, out_dir, board.intrinsics), None
    except RigError as exc:
        log.warning("SfM beside the board failed (%s); board poses alone", exc.problem)
        return None, exc.problem


def _board_poses(
    session: Session,
    decoded: DecodeIndex,
    decoded_dir: Path,
    conf: PosesConfig,
    out_dir: Path,
    spec: BoardSpec,
) -> tuple[dict[int, tuple[Intrinsics, Pose]], PoseSummary, np.ndarray]:
    """Board poses, merged with SfM when it runs; SfM alone in ``auto`` if the board fails."""
    strict = conf.source == "board"
    views = sorted(decoded.sfm_images)
    try:
        board = _board(session, decoded, decoded_dir, conf, spec)
    except RigError as exc:
        if strict:
            raise
        log.warning("board poses failed (%s); using SfM alone", exc.problem)
        cameras, summary, points = _sfm_poses(session, decoded, decoded_dir, conf, out_dir)
        summary.extra["board_error"] = exc.problem
        return cameras, summary, points
    sfm: tuple[dict[int, tuple[Intrinsics, Pose]], PoseSummary, np.ndarray] | None = None
    sfm_error = None
    unposed = sorted(set(views) - set(board.poses))
    if conf.board_with_sfm is True or (conf.board_with_sfm == "auto" and unposed):
        neighbourhood = None
        if conf.board_with_sfm == "auto" and len(board.poses) >= MIN_VIEWS:
            picked = sfm_neighbourhood(views, unposed, SFM_NEIGHBOURS)
            neighbourhood = picked if len(picked) < len(views) else None
        sfm, sfm_error = _sfm_beside_board(
            session, decoded, decoded_dir, conf, out_dir, board, unposed, neighbourhood
        )
    if len(board.poses) < MIN_VIEWS:
        if sfm is not None and not strict:
            log.warning("the board posed only %d views; using SfM alone", len(board.poses))
            sfm[1].extra["board_error"] = f"the board posed only {len(board.poses)} views"
            return sfm
        raise RigError(
            f"the board posed only {len(board.poses)} of {len(views)} views of {session.root}"
            f" (need {MIN_VIEWS}){'' if sfm_error is None else f'; SfM failed: {sfm_error}'}",
            "capture views that see the board (at least 6 corners each), check the profile's "
            "board entry matches the print, or use poses.source: sfm",
        )
    merged: MergedPoses[int] | None = None
    points = np.zeros((0, 3))
    if sfm is not None:
        try:
            merged = merge_with_sfm(board, {v: p for v, (_, p) in sfm[0].items()})
            points = merged.similarity.apply(sfm[2])
        except RigError as exc:
            sfm_error = exc.problem
            log.warning("SfM not merged with the board (%s); board poses alone", exc.problem)
    posed = merged.poses if merged is not None else board.poses
    cameras = {
        v: (board.intrinsics if v in board.poses or sfm is None else sfm[0][v][0], pose)
        for v, pose in posed.items()
    }
    summary = _board_summary(
        board, merged, views, None if sfm is None else sfm[1], sfm_error
    )
    return cameras, summary, points


def _poses(session: Session, decoded_dir: Path, conf: PosesConfig, out_dir: Path) -> None:
    decoded = DecodeIndex.load(decoded_dir)
    has_known = (session.poses_dir / "images.txt").is_file()
    spec = session_board(session.info)
    source = conf.source
    if source == "auto":
        source = "known" if conf.use_known and has_known else "board" if spec else "sfm"
    if source == "known":
        if not has_known:
            raise RigError(
                f"poses.source is known but {session.poses_dir / 'images.txt'} does not exist",
                "put a COLMAP text model in SESSION/poses/, or use poses.source: auto",
            )
        cameras, summary = _known(session, decoded)
        points = np.zeros((0, 3))
        if spec is not None:  # e.g. the sim's true poses: then the board frame is the world's
            in_frame, errors = board_frame_check(
                decoded, decoded_dir, spec, cameras, conf.board_max_rms_px
            )
            summary.extra["board_frame"] = in_frame
            for view, error in errors.items():
                if str(view) in summary.views:
                    summary.views[str(view)]["reprojection_px"] = _rounded(error)
    elif source == "board":
        if spec is None:
            raise RigError(
                f"poses.source is board but {session.root / 'session.yaml'} has no board entry",
                "add the board: snippet printed by `rig board` to the profile before capture, "
                "or use poses.source: sfm",
            )
        cameras, summary, points = _board_poses(
            session, decoded, decoded_dir, conf, out_dir, spec
        )
    else:
        cameras, summary, points = _sfm_poses(session, decoded, decoded_dir, conf, out_dir)
    if summary.registered < MIN_VIEWS:
        raise RigError(
            f"only {summary.registered} of {summary.total} views of {session.root} have a pose "
            f"({summary.source}); at least {MIN_VIEWS} are needed",
            "capture more overlapping, textured views, or give poses in SESSION/poses/ "
            "(COLMAP text model)",
        )
    registered = {v: cameras[v] for v in summary.registered_views}
    distinct: list[Intrinsics] = []
    images = {}
    for view, (intr, pose) in registered.items():
        if intr not in distinct:
            distinct.append(intr)
        images[view + 1] = (distinct.index(intr) + 1, f"view_{view:04d}.png", pose)
    write_colmap_text(out_dir, {i + 1: c for i, c in enumerate(distinct)}, images)
    np.save(out_dir / POINTS, points)
    write_bytes_atomically(out_dir / SUMMARY, json.dumps(asdict(summary), indent=1).encode())
    log.info(
        "poses (%s): %d/%d views registered, mean reprojection error %s px, scale %s",
        summary.source, summary.registered, summary.total,
        "n/a" if summary.mean_reprojection_error_px is None
        else f"{summary.mean_reprojection_error_px:.3f}", summary.scale,
    )


def load(out_dir: Path) -> tuple[dict[int, Intrinsics], dict[int, Pose], PoseSummary]:
    """Per-view intrinsics and poses of the stage's output, and its summary."""
    cams, images = read_colmap_text(out_dir)
    intr = {iid - 1: cams[cid] for iid, (cid, _, _) in images.items()}
    poses = {iid - 1: pose for iid, (_, _, pose) in images.items()}
    summary = PoseSummary(**json.loads((out_dir / SUMMARY).read_text()))
    return intr, poses, summary


def run(
    conf: PosesConfig | Mapping[str, Any], session_dir: Path, decoded_dir: Path, out_dir: Path
) -> Path:
    """Poses of every view (known, board, SfM or board + SfM) into ``out_dir`` (resumable)."""
    conf = from_mapping(PosesConfig, conf, "config", "poses")
    session = Session.open(session_dir)
    inputs = [session_dir / "session.yaml", decoded_dir / INDEX, session.poses_dir]
    if out_dir.exists() and not (out_dir / ".stamp.json").exists():
        shutil.rmtree(out_dir)
    run_stage(
        "poses", asdict(conf), inputs, out_dir, lambda: _poses(session, decoded_dir, conf, out_dir)
    )
    return out_dir
