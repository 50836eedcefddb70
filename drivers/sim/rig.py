"""The simulated rig: scene, camera, bulb, projector and spectrometer wired together.

``SimRig(config, seed)`` is deterministic for a seed: the same captures give the same bytes.
The rig moves its camera itself (``goto_view``); the bulb rides on the camera plate at the
trajectory's ``light_offset_m`` (or sits at a free position per view), the projector rides on
the plate at ``projector.offset_m`` with the camera's orientation.

Config keys (all optional): ``scene`` (blob | torus | chart, or a folder written by
``Scene.save``), ``scene_seed``, ``subdivisions``, ``views``, ``light_offset_m``,
``trajectory`` (see :class:`TrajectoryConfig`), ``camera`` (see :class:`SensorConfig`),
``projector`` (``width``, ``height``, ``focal_px``, ``offset_m``), ``illuminations``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from calibration.errors import RigError
from drivers.sim.camera import SensorConfig, SimCamera
from drivers.sim.light import SimLight
from drivers.sim.projector import SimProjector
from drivers.sim.scene import SCENES, Scene, make_scene
from drivers.sim.spectrometer import SimSpectrometer
from drivers.sim.trajectory import TrajectoryConfig, light_positions, ring_poses
from reconstruct.camera import Intrinsics, Pose, write_colmap_text

_KEYS = {
    "scene",
    "scene_seed",
    "subdivisions",
    "views",
    "light_offset_m",
    "trajectory",
    "camera",
    "projector",
    "illuminations",
}
_PROJECTOR_DEFAULTS: dict[str, Any] = {
    "width": 800,
    "height": 600,
    "focal_px": 1000.0,
    "offset_m": [-0.08, 0.0, 0.0],
}


def sfm_image_name(view: int) -> str:
    """Image name of a view in the ground-truth COLMAP model (as the decode stage names them)."""
    return f"view_{view:04d}.png"


class SimRig:
    """All simulated devices of one virtual capture (see module docstring for ``config``)."""

    def __init__(self, config: Mapping[str, Any] | None = None, seed: int = 0) -> None:
        conf = dict(config or {})
        unknown = set(conf) - _KEYS
        if unknown:
            raise RigError(
                f"sim: unknown key(s) {', '.join(sorted(unknown))}",
                f"use only {', '.join(sorted(_KEYS))}",
            )
        self.seed = int(seed)
        self.scene = _load_scene(conf, self.seed)
        traj = dict(conf.get("trajectory") or {})
        if "views" in conf:
            traj["views"] = int(conf["views"])
        if "light_offset_m" in conf:
            traj["light_offset_m"] = conf["light_offset_m"]
        self.trajectory = TrajectoryConfig.from_mapping(traj)
        self.poses: list[Pose] = ring_poses(self.trajectory)
        self.light_positions = light_positions(self.trajectory, self.poses, self.seed)
        self.light_offset: np.ndarray | None = (
            np.asarray(self.trajectory.light_offset_m) if self.trajectory.light == "rigid" else None
        )
        self.sensor = SensorConfig.from_mapping(conf.get("camera"))
        self.intrinsics: Intrinsics = self.sensor.intrinsics
        proj = {**_PROJECTOR_DEFAULTS, **dict(conf.get("projector") or {})}
        extra = sorted(set(proj) - set(_PROJECTOR_DEFAULTS))
        if extra:
            raise RigError(
                f"sim.projector: unknown key(s) {', '.join(extra)}",
                f"use only {', '.join(_PROJECTOR_DEFAULTS)}",
            )
        self.projector_offset = np.asarray(proj["offset_m"], dtype=float)
        self.light = SimLight(illuminations=conf.get("illuminations"))
        self.projector = SimProjector(
            Intrinsics.pinhole(int(proj["width"]), int(proj["height"]), float(proj["focal_px"]))
        )
        self.camera = SimCamera(self.scene, self.light, self.projector, self.sensor, self.seed)
        self.spectrometer = SimSpectrometer(
            lambda: self.light.spd() + self.projector.spd(), seed=self.seed
        )
        self.view = 0
        self.goto_view(0)

    def goto_view(self, view: int) -> None:
        """Move the camera plate (camera, bulb, projector) to view ``view``."""
        if not 0 <= view < len(self.poses):
            raise RigError(
                f"sim view {view} does not exist (the trajectory has {len(self.poses)} views)",
                "raise sim.views / plan.views or capture fewer views",
            )
        self.view = view
        pose = self.poses[view]
        self.camera.set_pose(pose)
        self.light.position = self.light_positions[view]
        self.projector.pose = Pose(pose.R, pose.t - self.projector_offset)

    def write_ground_truth(self, folder: Path) -> None:
        """Write the truth for evaluation: ``mesh.ply``, ``reflectance.npy``, ``patch.npy``,
        ``scene.yaml``, ``poses/`` (COLMAP text, images named ``view_0000.png``...) and
        ``rig.yaml`` (light offset, light and projector positions per view, sensor)."""
        folder = Path(folder)
        self.scene.save(folder)
        images = {v + 1: (1, sfm_image_name(v), p) for v, p in enumerate(self.poses)}
        write_colmap_text(folder / "poses", {1: self.intrinsics}, images)
        rig = {
            "seed": self.seed,
            "scene": self.scene.name,
            "light_mode": self.trajectory.light,
            "light_offset_m": None
            if self.light_offset is None
            else [float(x) for x in self.light_offset],
            "light_positions_m": [[float(x) for x in p] for p in self.light_positions],
            "projector_offset_m": [float(x) for x in self.projector_offset],
            "projector_intrinsics": {
                "model": self.projector.intrinsics.model,
                "width": self.projector.width,
                "height": self.projector.height,
                "params": [float(p) for p in self.projector.intrinsics.params],
            },
            "camera_sensitivity": self.sensor.sensitivity,
            "black_level": self.sensor.black_level,
            "white_level": self.sensor.white_level,
            "cfa_pattern": self.sensor.pattern,
            "trajectory": {
                "views": self.trajectory.views,
                "elevations_deg": list(self.trajectory.elevations_deg),
                "radius_m": self.trajectory.radius_m,
            },
        }
        (folder / "rig.yaml").write_text(yaml.safe_dump(rig, sort_keys=False))

    def close(self) -> None:
        for device in (self.light, self.projector, self.camera, self.spectrometer):
            device.close()


def _load_scene(conf: Mapping[str, Any], seed: int) -> Scene:
    name = str(conf.get("scene", "blob"))
    if name in SCENES:
        return make_scene(name, int(conf.get("scene_seed", seed)), int(conf.get("subdivisions", 7)))
    folder = Path(name)
    if folder.is_dir():
        return Scene.load(folder)
    raise RigError(
        f"sim.scene {name!r} is neither a built-in scene nor a folder",
        f"use one of {', '.join(SCENES)} or a folder with mesh.ply + reflectance.npy + scene.yaml",
    )
