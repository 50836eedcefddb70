"""Known poses: a COLMAP text model in ``SESSION/poses/`` (the sim's truth, or poses from another
tool), matched to views by image name."""

from __future__ import annotations

import logging
import re
from pathlib import Path

from core.errors import RigError
from core.session import Session
from reconstruct.frames.decode import DecodeIndex
from reconstruct.model.camera import Intrinsics, Pose, read_colmap_text
from reconstruct.poses.output import PoseSummary
from reconstruct.poses.sfm import rescale

log = logging.getLogger("reconstruct.poses.known")


def view_of_name(name: str, session: Session) -> int | None:
    """Which view a known-pose image name refers to: a manifest frame's file path, its file
    name or stem, ``view_NNNN[.ext]``, or the view number itself."""
    for record in session.frames:
        p = Path(record.path)
        if name in (record.path, p.name, p.stem):
            return record.view
    match = re.fullmatch(r"(?:view_)?(\d+)(?:\.\w+)?", Path(name).name)
    if match and int(match.group(1)) in set(session.views()):
        return int(match.group(1))
    return None


def known_poses(
    session: Session, decoded: DecodeIndex
) -> tuple[dict[int, tuple[Intrinsics, Pose]], PoseSummary]:
    """The cameras of ``SESSION/poses/`` by view, in metres, at the size of the view's decoded
    frames (decode may store them at a coarser pyramid level than the camera's)."""
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
        frame = next((f for f in decoded.frames if f.view == view), None)
        intr = cams[cid] if frame is None else rescale(cams[cid], frame.width, frame.height)
        out[view] = (intr, pose)
    views = sorted(decoded.sfm_images)
    posed = sorted(set(out) & set(views))
    summary = PoseSummary(
        "known", len(posed), len(views), posed, sorted(set(views) - set(out)), None, "metric",
        1.0, "known poses", views={str(v): {"source": "known"} for v in posed},
    )
    return out, summary
