"""What the poses stage leaves in ``recon/poses/``: a COLMAP text model, ``poses.json``
(:class:`PoseSummary`) and ``points3D.npy``; :func:`load` reads them back once per run."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from core.files import write_bytes_atomically
from reconstruct.model.camera import Intrinsics, Pose, read_colmap_text, write_colmap_text

SUMMARY = "poses.json"
POINTS = "points3D.npy"

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


class PoseSet(NamedTuple):
    """The stage's output as loaded: per-view intrinsics and poses, and the summary."""

    intrinsics: dict[int, Intrinsics]
    poses: dict[int, Pose]
    summary: PoseSummary


def write(
    out_dir: Path,
    cameras: dict[int, tuple[Intrinsics, Pose]],
    summary: PoseSummary,
    points: np.ndarray,
) -> None:
    """The registered views' cameras (image id = view + 1, one camera per distinct intrinsics),
    the sparse points and the summary."""
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


def load(out_dir: Path) -> PoseSet:
    """Per-view intrinsics and poses of the stage's output, and its summary."""
    cams, images = read_colmap_text(out_dir)
    intr = {iid - 1: cams[cid] for iid, (cid, _, _) in images.items()}
    poses = {iid - 1: pose for iid, (_, _, pose) in images.items()}
    summary = PoseSummary(**json.loads((out_dir / SUMMARY).read_text()))
    return PoseSet(intr, poses, summary)
