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

Modules: :mod:`~reconstruct.poses.config`, :mod:`~reconstruct.poses.known`,
:mod:`~reconstruct.poses.sfm`, :mod:`~reconstruct.poses.board_sfm` (board + SfM merge) and
:mod:`~reconstruct.poses.output` (the files, and :func:`~reconstruct.poses.output.load`).
"""

from __future__ import annotations

import logging
import shutil
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from core.config import from_mapping
from core.errors import RigError
from core.session import SESSION_FILE, Session
from reconstruct.frames.decode import INDEX, DecodeIndex
from reconstruct.poses import output
from reconstruct.poses.board_sfm import (
    board_frame_check,
    board_with_sfm,
    rounded,
    session_board,
)
from reconstruct.poses.config import MIN_VIEWS, PosesConfig
from reconstruct.poses.known import known_poses
from reconstruct.poses.sfm import sfm_poses
from reconstruct.stages.resumable import run_stage

log = logging.getLogger("reconstruct.poses.stage")


def _poses(session: Session, decoded_dir: Path, conf: PosesConfig, out_dir: Path) -> None:
    """Pick the source, pose the views, write the output."""
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
        cameras, summary = known_poses(session, decoded)
        points = np.zeros((0, 3))
        if spec is not None:  # e.g. the sim's true poses: then the board frame is the world's
            in_frame, errors = board_frame_check(
                decoded, decoded_dir, spec, cameras, conf.board_max_rms_px
            )
            summary.extra["board_frame"] = in_frame
            for view, error in errors.items():
                if str(view) in summary.views:
                    summary.views[str(view)]["reprojection_px"] = rounded(error)
    elif source == "board":
        if spec is None:
            raise RigError(
                f"poses.source is board but {session.root / 'session.yaml'} has no board entry",
                "add the board: snippet printed by `rig board` to the profile before capture, "
                "or use poses.source: sfm",
            )
        cameras, summary, points = board_with_sfm(
            session, decoded, decoded_dir, conf, out_dir, spec
        )
    else:
        cameras, summary, points = sfm_poses(session, decoded, decoded_dir, conf, out_dir)
    if summary.registered < MIN_VIEWS:
        raise RigError(
            f"only {summary.registered} of {summary.total} views of {session.root} have a pose "
            f"({summary.source}); at least {MIN_VIEWS} are needed",
            "capture more overlapping, textured views, or give poses in SESSION/poses/ "
            "(COLMAP text model)",
        )
    output.write(out_dir, cameras, summary, points)
    log.info(
        "poses (%s): %d/%d views registered, mean reprojection error %s px, scale %s",
        summary.source, summary.registered, summary.total,
        "n/a" if summary.mean_reprojection_error_px is None
        else f"{summary.mean_reprojection_error_px:.3f}", summary.scale,
    )


def run(
    conf: PosesConfig | Mapping[str, Any],
    session: Session | Path,
    decoded_dir: Path,
    out_dir: Path,
) -> Path:
    """Poses of every view (known, board, SfM or board + SfM) into ``out_dir`` (resumable);
    ``session`` opened by the caller, or its folder."""
    conf = from_mapping(PosesConfig, conf, "config", "poses")
    session = Session.of(session)
    inputs = [session.root / SESSION_FILE, decoded_dir / INDEX, session.poses_dir]
    if out_dir.exists() and not (out_dir / ".stamp.json").exists():
        shutil.rmtree(out_dir)
    run_stage(
        "poses", asdict(conf), inputs, out_dir, lambda: _poses(session, decoded_dir, conf, out_dir)
    )
    return out_dir
