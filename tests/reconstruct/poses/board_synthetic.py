"""Sessions of a printed ChArUco board seen from around an object (synthetic renders of
``tests/reconstruct/poses/conftest.py``), written as linear NPY frames with a manifest and a
``board:`` entry in session.yaml, as ``rig capture`` leaves them; plus a stand-in for SfM
that returns the true poses in another (scaled, rotated, shifted) frame."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from core.files import sha256_file
from core.manifest import FrameRecord, append_manifest
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.poses.board import BoardSpec, Similarity, board_texture
from reconstruct.poses.sfm import SfmResult, rescale
from tests.reconstruct.poses.conftest import PX_PER_M, Scene, orbit_poses, render

SPEC = BoardSpec.fit_paper("A4")
INTRINSICS = Intrinsics("PINHOLE", 960, 720, (830.0, 830.0, 482.5, 356.0))
HIDDEN = 8  # this view looks past the board: only SfM can pose it
EXPOSURE_S, ISO = 0.02, 200.0


def scene() -> Scene:
    texture, extent = board_texture(SPEC, PX_PER_M)
    return Scene(SPEC, texture, extent, INTRINSICS)


def true_poses(views: int = 8) -> list[Pose]:
    """``views`` cameras around the board at 0.45 m, then one aimed past it."""
    poses = orbit_poses(views, np.random.default_rng(3), distance=0.45)
    return [*poses, Pose.look_at(np.array([0.0, -0.3, 0.25]), np.array([0.9, 0.6, 0.7]))]


def build_board_session(
    root: Path, poses: Sequence[Pose], intrinsics_in_yaml: bool = True
) -> Path:
    """Render every pose, write the frames (linear, float16) and the session files."""
    (root / "raw").mkdir(parents=True)
    sc, rng = scene(), np.random.default_rng(5)
    info: dict[str, object] = {"rig": "synthetic-board", "board": SPEC.to_dict()}
    if intrinsics_in_yaml:
        info["intrinsics"] = {"model": INTRINSICS.model, "width": INTRINSICS.width,
                              "height": INTRINSICS.height, "params": list(INTRINSICS.params)}
    (root / "session.yaml").write_text(yaml.safe_dump(info))
    for view, pose in enumerate(poses):
        grey = render(sc, pose, rng, occluder_m=0.05).astype(np.float32) / 255.0
        linear = np.repeat((grey**2.2)[:, :, None], 3, axis=2) * 0.5
        rel = f"raw/v{view:03d}_white.npy"
        np.save(root / rel, linear.astype(np.float16))
        append_manifest(root, FrameRecord(
            view, view, "white", rel, sha256_file(root / rel), EXPOSURE_S, ISO,
            "2026-01-01T00:00:00Z"))
    return root


SFM_FRAME = Similarity(
    2.5, Rotation.from_rotvec([0.3, -1.1, 0.4]).as_matrix(), np.array([0.2, -0.4, 1.5])
)


def fake_sfm(poses: Sequence[Pose], points: np.ndarray) -> SfmResult:
    """What SfM would give without noise: every view, in the frame ``SFM_FRAME`` (of the
    board's), with the intrinsics at the SfM images' size (the decoded size here)."""
    cameras = {
        f"view_{v:04d}.png": (rescale(INTRINSICS, INTRINSICS.width, INTRINSICS.height),
                              SFM_FRAME.apply_pose(p))
        for v, p in enumerate(poses)
    }
    return SfmResult(cameras, SFM_FRAME.apply(points), 0.4)
