"""Board poses (a printed ChArUco board under the object), with SfM run beside them for the
views the board leaves unposed and carried into the board's frame by a robust similarity."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from core.errors import RigError
from core.session import Session
from core.session_info import SessionInfo
from reconstruct.frames.decode import SFM_DIR, DecodeIndex, load_frame
from reconstruct.model.camera import Intrinsics, Pose
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
from reconstruct.poses.config import MIN_VIEWS, PosesConfig
from reconstruct.poses.output import PoseSummary
from reconstruct.poses.sfm import full_size, rescale, session_intrinsics, sfm_poses
from reconstruct.stages.progress import track

log = logging.getLogger("reconstruct.poses.board_sfm")

def session_board(info: SessionInfo) -> BoardSpec | None:
    """The ``board:`` entry of session.yaml (or its profile snapshot), None without one."""
    if info.board is None:
        return None
    return BoardSpec.from_dict(dict(info.board), source="session.yaml")


def board_images(decoded: DecodeIndex, decoded_dir: Path) -> dict[int, np.ndarray]:
    """8-bit RGB image of each view at full resolution for corner detection: the SfM copy
    when it is full size (the view's brightest frame), else the brightest linear frame."""
    out: dict[int, np.ndarray] = {}
    for view, name in sorted(decoded.sfm_images.items()):
        width, height = full_size(decoded, view)
        png = cv2.imread(str(decoded_dir / SFM_DIR / name), cv2.IMREAD_COLOR)
        if png is not None and png.shape[:2] == (height, width):
            out[view] = np.ascontiguousarray(png[:, :, ::-1])
            continue
        frames = [load_frame(decoded_dir, f)[0] for f in decoded.frames if f.view == view]
        out[view] = linear_to_u8(max(frames, key=lambda img: float(np.mean(img))))
    return out


def find_board_poses(
    session: Session, decoded: DecodeIndex, decoded_dir: Path, conf: PosesConfig, spec: BoardSpec
) -> BoardPoseResult[int]:
    """Board poses of every view that shows enough of the board, with the session's
    intrinsics when it gives them."""
    images = board_images(decoded, decoded_dir)
    detections = {
        v: detect_board(img, spec)
        for v, img in track(list(images.items()), "finding the board")
    }
    size = full_size(decoded, min(images))
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


def rounded(value: float) -> float | None:
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
            "reprojection_px": rounded(errors.get(view, np.nan)),
            "board_corners": board.n_corners.get(view, 0),
        }
        if view in board.rejected:
            entry["board_rejected"] = board.rejected[view]
        if merged is not None and view in merged.alignment_residual_m:
            entry["alignment_residual_mm"] = round(1000 * merged.alignment_residual_m[view], 3)
            entry["alignment_rotation_deg"] = round(merged.alignment_rotation_deg[view], 4)
            entry["alignment_outlier"] = view in merged.alignment_outliers
        per_view[str(view)] = entry
    extra: dict[str, Any] = {"board_rms_px": rounded(board.rms_px)}
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
        sorted(set(views) - set(posed)), rounded(board.rms_px), "metric", 1.0,
        f"board ({board.intrinsics_source})", extra, per_view,
    )


SFM_NEIGHBOURS = 4  # views each side (capture order) SfM runs beside an unposed view


def sfm_neighbourhood(views: Sequence[int], unposed: Sequence[int], k: int) -> list[int]:
    """The views SfM needs to pose ``unposed`` into the board's frame: each with its ``k``
    neighbours on either side in capture order (cyclic: a ring's last view meets its first):
    matching a few views instead of all of them, exhaustively, poses the hidden views as well
    in a fraction of the time."""
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
            sfm = sfm_poses(
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
        return sfm_poses(session, decoded, decoded_dir, conf, out_dir, board.intrinsics), None
    except RigError as exc:
        log.warning("SfM beside the board failed (%s); board poses alone", exc.problem)
        return None, exc.problem


def board_with_sfm(
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
        board = find_board_poses(session, decoded, decoded_dir, conf, spec)
    except RigError as exc:
        if strict:
            raise
        log.warning("board poses failed (%s); using SfM alone", exc.problem)
        cameras, summary, points = sfm_poses(session, decoded, decoded_dir, conf, out_dir)
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
