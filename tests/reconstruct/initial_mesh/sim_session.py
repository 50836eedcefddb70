"""A projector session captured with the simulated rig, written as a real session directory.

The sim camera and projector are placed by hand (camera and projector moved alternately, as
in Pro-Cam SSfM), the sim camera writes DNG files, and every frame goes into the manifest with
its ``projector_placement``: exactly what ``rig capture`` leaves for a projector profile.
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import yaml

from core.files import sha256_file
from core.manifest import FrameRecord, append_manifest
from drivers.projectors.patterns import gray_code_sequence
from drivers.sim import SimRig
from reconstruct.model.camera import Intrinsics, Pose

PROJECTOR = {"width": 128, "height": 96, "focal_px": 220.0}
CAMERA = {"width": 240, "height": 180, "focal_px": 500.0, "supersample": 1,
          "exposure_s": 0.5, "iso": 100}


def _eye(azimuth_deg: float, elevation_deg: float, radius: float = 0.5) -> np.ndarray:
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    return radius * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def layout(plate: bool) -> tuple[list[Pose], list[int], dict[int, Pose]]:
    """Camera poses, the placement of each view, and the projector pose of each placement."""
    cams = [(-125, 15), (-90, 35), (-55, 15), (-35, 20), (0, 40), (35, 20)]
    poses = [Pose.look_at(_eye(a, e), np.zeros(3)) for a, e in cams]
    if plate:
        offset = np.array([-0.06, 0.0, 0.0])
        return poses, list(range(len(poses))), {
            v: Pose(p.R, p.t - offset) for v, p in enumerate(poses)}
    projectors = {0: Pose.look_at(_eye(-90, 10, 0.45), np.zeros(3)),
                  1: Pose.look_at(_eye(0, 15, 0.45), np.zeros(3))}
    return poses, [0, 0, 0, 1, 1, 1], projectors


COLOURS = {"red": (1.0, 0.0, 0.0), "green": (0.0, 1.0, 0.0), "blue": (0.0, 0.0, 1.0),
           "full": (1.0, 1.0, 1.0)}


def capture(root: Path, plate: bool = False, seed: int = 0,
            colours: tuple[str, ...] = ()) -> tuple[SimRig, list[Pose]]:
    """Write the session to ``root`` (the Gray code, white, and the uniform ``colours`` of
    :data:`COLOURS`); returns the rig (its scene is the truth) and the camera poses."""
    rig = SimRig({"scene": "blob", "subdivisions": 5, "camera": CAMERA,
                  "projector": PROJECTOR}, seed=seed)
    poses, placement, projectors = layout(plate)
    raw = root / "raw"
    raw.mkdir(parents=True)
    patterns = gray_code_sequence(PROJECTOR["width"], PROJECTOR["height"])
    shape = (PROJECTOR["height"], PROJECTOR["width"], 3)
    patterns.append(("white", np.ones(shape)))
    patterns += [(name, np.broadcast_to(COLOURS[name], shape)) for name in colours]
    frame = 0
    for view, pose in enumerate(poses):
        rig.camera.set_pose(pose)
        rig.projector.pose = projectors[placement[view]]
        for label, image in patterns:
            rig.projector.show(image)
            shot = rig.camera.capture(raw, f"frame_{frame:05d}")
            path = Path(shot.paths[0])
            extra = {} if plate else {"projector_placement": placement[view]}
            append_manifest(root, FrameRecord(
                frame, view, label, path.relative_to(root).as_posix(), sha256_file(path),
                float(CAMERA["exposure_s"]), float(CAMERA["iso"]),
                datetime.now(timezone.utc).isoformat(), extra))
            frame += 1
    info = {
        "format": 1,
        "devices": {"projector": {"driver": "sim", "resolution": [PROJECTOR["width"],
                                                                   PROJECTOR["height"]]}},
        "light_mount": {"type": "plate", "offset_m": [-0.06, 0.0, 0.0]},
    }
    (root / "session.yaml").write_text(yaml.safe_dump(info))
    return rig, poses


def intrinsics() -> Intrinsics:
    return Intrinsics.pinhole(CAMERA["width"], CAMERA["height"], CAMERA["focal_px"])
