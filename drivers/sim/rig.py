"""The simulated rig: scene, camera, bulb, projector and spectrometer wired together.

``SimRig(config, seed)`` is deterministic for a seed: the same captures give the same bytes.
The rig moves its camera itself (``goto_view``); the bulb rides on the camera plate at the
trajectory's ``light_offset_m`` (or sits at a free position per view). The projector rides on
the plate at ``projector.offset_m`` with the camera's orientation or, with
``projector.placements: K``, stands on its own at K placements around the object while the
camera takes ``views_per_placement`` views of the side it lights (camera and projector moved
alternately, as in Pro-Cam SSfM).

Config keys (all optional): ``scene`` (blob | torus | chart, or a folder written by
``Scene.save``), ``scene_seed``, ``subdivisions``, ``views``, ``light_offset_m``,
``trajectory`` (see :class:`TrajectoryConfig`), ``camera`` (see :class:`SensorConfig`),
``projector`` (``width``, ``height``, ``focal_px``, ``offset_m``, ``placements``,
``views_per_placement``, ``placement_radius_m``, ``placement_elevation_deg``,
``view_spread_deg``), ``illuminations``, ``ground`` (a textured plane at z = 0 the object
stands on, e.g. a printed marker board: ``texture`` (H, W) array or ``.npy`` path in [0, 1],
``extent`` [x0, y0, x1, y1] metres, ``paper`` and ``ink`` reflectances (a number or one value
per wavelength); the scene is lifted to stand on it and the cameras aim at its middle),
``ambient`` (a room light in every frame: ``level``, ``spd``, ``distance_m``, see
:mod:`drivers.sim.ambient`), ``light_diameter_m`` (a bulb with a size, soft shadows; default
the profile's ``light_mount.diameter_m``), ``gloss`` (a neutral GGX lobe: ``specular``,
``alpha``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from core.config import bounded, from_mapping
from core.errors import RigError
from core.files import write_bytes_atomically
from drivers.sim.ambient import AmbientConfig, room_spd
from drivers.sim.camera import GlossConfig, SensorConfig
from drivers.sim.members import RigCamera, RigLight, RigProjector, RigSpectrometer
from drivers.sim.scene import SCENES, Scene, make_scene
from drivers.sim.trajectory import (
    MAX_VIEWS,
    PlacementConfig,
    ProjectorConfig,
    TrajectoryConfig,
    light_positions,
    placement_poses,
    ring_poses,
)
from reconstruct.model.camera import Intrinsics, Pose, write_colmap_text
from reconstruct.model.render import GroundPlane

CARD_THICKNESS_M = 0.001


@dataclass(frozen=True)
class GroundConfig:
    """The ``sim.ground`` section: ``texture`` an (H, W) array or ``.npy`` path in [0, 1];
    ``extent`` [x0, y0, x1, y1] metres; ``paper``, ``ink`` one reflectance or one per
    wavelength (checked against the scene's grid)."""

    texture: Any
    extent: tuple[float, float, float, float] = bounded(min=-100, max=100)
    paper: Any = 0.85
    ink: Any = 0.04


@dataclass(frozen=True)
class SimConfig:
    """The ``sim`` section of a profile (see the module docstring). ``trajectory`` stays a
    mapping until the ground's centre and the top-level ``views`` / ``light_offset_m`` are
    merged in."""

    scene: str = "blob"
    scene_seed: int | None = bounded(None, min=0, max=10**9)  # None: the rig's seed
    subdivisions: int = bounded(7, min=0, max=8)  # 8: ~655k vertices on the blob
    views: int | None = bounded(None, min=1, max=MAX_VIEWS)
    light_offset_m: tuple[float, float, float] | None = bounded(None, min=-10, max=10)
    trajectory: dict[str, Any] | None = None
    camera: SensorConfig = field(default_factory=SensorConfig)
    projector: ProjectorConfig = field(default_factory=ProjectorConfig)
    illuminations: dict[str, dict[str, float]] | None = bounded(None, min=0, max=1)
    ground: GroundConfig | None = None
    ambient: AmbientConfig | None = None
    light_diameter_m: float = bounded(0.0, min=0, max=2)  # 0: a point light
    gloss: GlossConfig | None = None  # None: a Lambertian object


def sfm_image_name(view: int) -> str:
    """Image name of a view in the ground-truth COLMAP model (as the decode stage names them)."""
    return f"view_{view:04d}.png"


class SimRig:
    """All simulated devices of one virtual capture (see module docstring for ``config``);
    ``reference_camera`` is the camera section of the white reference's rig (default: this
    rig's)."""

    def __init__(
        self,
        config: Mapping[str, Any] | None = None,
        seed: int = 0,
        reference_camera: Mapping[str, Any] | None = None,
    ) -> None:
        conf = from_mapping(SimConfig, config, "sim config", "sim")
        self.seed = int(seed)
        self.reference_camera = dict(
            reference_camera if reference_camera is not None else (config or {}).get("camera") or {}
        )
        self.scene = _load_scene(conf, self.seed)
        self.ground = _ground(conf.ground, len(self.scene.wavelengths))
        traj = dict(conf.trajectory or {})
        if self.ground is not None:
            self.scene = stand_on_ground(self.scene)
            lo, hi = self.scene.vertices.min(axis=0), self.scene.vertices.max(axis=0)
            traj.setdefault("target_m", [float(x) for x in (lo + hi) / 2])
        if conf.views is not None:
            traj["views"] = conf.views
        if conf.light_offset_m is not None:
            traj["light_offset_m"] = conf.light_offset_m
        self.trajectory = from_mapping(TrajectoryConfig, traj, "sim config", "sim.trajectory")
        proj = conf.projector
        self.placements = PlacementConfig.for_views(proj, self.trajectory.views)
        if self.placements is None:
            self.poses: list[Pose] = ring_poses(self.trajectory)
            self.projector_poses: list[Pose] = []
        else:
            self.poses, self.projector_poses = placement_poses(self.trajectory, self.placements)
        self.light_positions = light_positions(self.trajectory, self.poses, self.seed)
        if self.ground is not None:  # a light under the table would light nothing
            self.light_positions[:, 2] = np.maximum(self.light_positions[:, 2], 0.02)
        self.light_offset: np.ndarray | None = (
            np.asarray(self.trajectory.light_offset_m) if self.trajectory.light == "rigid" else None
        )
        self.sensor = conf.camera
        self.intrinsics: Intrinsics = self.sensor.intrinsics
        self.projector_offset = np.asarray(proj.offset_m, dtype=float)
        self.light = RigLight(illuminations=conf.illuminations)
        self.projector = RigProjector(Intrinsics.pinhole(proj.width, proj.height, proj.focal_px))
        self.camera = RigCamera(
            self.scene, self.light, self.projector, self.sensor, self.seed, ground=self.ground
        )
        self.camera.ambient_spd = room_spd(conf.ambient, self.light, self.trajectory.radius_m)
        self.light_diameter_m = conf.light_diameter_m
        self.camera.bulb_radius_m = conf.light_diameter_m / 2.0
        self.camera.gloss = conf.gloss
        self.spectrometer = RigSpectrometer(
            lambda: self.light.spd() + self.projector.spd(), seed=self.seed
        )
        for device in (self.light, self.projector, self.camera, self.spectrometer):
            device.rig = self
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
        placement = self.projector_placement(view)
        self.projector.pose = (
            Pose(pose.R, pose.t - self.projector_offset)
            if placement is None
            else self.projector_poses[placement]
        )

    def view_directions(self) -> list[tuple[float, float]]:
        """(azimuth, elevation) in degrees of every view's camera centre around the target."""
        target = np.asarray(self.trajectory.target_m, dtype=float)
        rel = np.array([np.asarray(p.center, dtype=float) for p in self.poses]) - target
        az = np.degrees(np.arctan2(rel[:, 1], rel[:, 0])) % 360.0
        el = np.degrees(np.arctan2(rel[:, 2], np.hypot(rel[:, 0], rel[:, 1])))
        return list(zip(az.tolist(), el.tolist(), strict=True))

    def projector_placement(self, view: int) -> int | None:
        """The projector placement lighting ``view`` (None: the projector is on the plate)."""
        if self.placements is None:
            return None
        return view // self.placements.views_per_placement

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
            "projector_offset_m": None
            if self.placements is not None
            else [float(x) for x in self.projector_offset],
            "projector_placements": [
                {"R": p.R.tolist(), "t": p.t.tolist(), "centre_m": p.center.tolist()}
                for p in self.projector_poses
            ],
            "view_placement": [self.projector_placement(v) for v in range(len(self.poses))],
            "ground": None
            if self.ground is None
            else {
                "extent_m": [float(x) for x in self.ground.extent],
                "texture_shape": list(np.shape(self.ground.texture)),
            },
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
                "distances_m": list(self.trajectory.distances_m),
                "target_m": list(self.trajectory.target_m),
            },
        }
        write_bytes_atomically(folder / "rig.yaml", yaml.safe_dump(rig, sort_keys=False).encode())

    def close(self) -> None:
        for device in (self.light, self.projector, self.camera, self.spectrometer):
            device.close()


def _load_scene(conf: SimConfig, seed: int) -> Scene:
    name = conf.scene
    if name in SCENES:
        scene_seed = seed if conf.scene_seed is None else conf.scene_seed
        return make_scene(name, scene_seed, conf.subdivisions)
    folder = Path(name)
    if folder.is_dir():
        return Scene.load(folder)
    raise RigError(
        f"sim.scene {name!r} is neither a built-in scene nor a folder",
        f"use one of {', '.join(SCENES)} or a folder with mesh.ply + reflectance.npy + scene.yaml",
    )


def stand_on_ground(scene: Scene) -> Scene:
    """The scene moved up so its lowest point touches z = 0 (it stands on the ground); a flat
    scene (the chart) lies on it as a card with a thickness, not in the ground's plane."""
    z = scene.vertices[:, 2]
    lift = -float(z.min()) + (CARD_THICKNESS_M if np.ptp(z) == 0 else 0.0)
    return replace(scene, vertices=scene.vertices + np.array([0.0, 0.0, lift]))


def _spectrum(value: Any, n: int, key: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,) or not np.all((arr >= 0) & (arr <= 1)):
        raise RigError(
            f"sim.ground.{key} has shape {arr.shape} or values outside [0, 1]",
            f"give one reflectance in [0, 1] or {n} of them (one per wavelength)",
        )
    return arr


def _ground(conf: GroundConfig | None, n_wavelengths: int) -> GroundPlane | None:
    """``sim.ground`` -> a :class:`GroundPlane` (None when absent)."""
    if conf is None:
        return None
    texture = conf.texture
    if isinstance(texture, (str, Path)):
        path = Path(texture)
        if not path.is_file():
            raise RigError(f"sim.ground.texture file {path} does not exist", "give a .npy file")
        texture = np.load(path, allow_pickle=False)
    extent = conf.extent
    return GroundPlane(
        np.clip(np.asarray(texture, dtype=np.float32), 0.0, 1.0),
        (float(extent[0]), float(extent[1]), float(extent[2]), float(extent[3])),
        _spectrum(conf.paper, n_wavelengths, "paper"),
        _spectrum(conf.ink, n_wavelengths, "ink"),
    )
