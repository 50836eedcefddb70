"""Camera poses and light positions for the simulated rig.

Views lie on rings around the object (as a turntable or a hand-held walk-around would give),
every camera looking at the target; with ``distances_m`` the camera steps in and out between
views, as a hand-held capture does (the paper's 74 camera–light positions): views at different
distances are what make the light's distance observable apart from the reflectance scale.

The light is either rigidly mounted on the camera plate at an offset ``v`` in the camera frame
(the paper's setup: ``p_c = R_c^T (v - t_c)``) or free: one seeded position per view, on a
sphere around the object on the camera's side.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from core.errors import RigError
from drivers.sim.config_keys import reject_unknown_keys
from reconstruct.model.camera import Pose


@dataclass(frozen=True)
class TrajectoryConfig:
    """Ring trajectory settings (the ``trajectory`` section of a sim profile)."""

    views: int = 40
    elevations_deg: tuple[float, ...] = (20.0, 45.0)
    radius_m: float = 0.5
    distances_m: tuple[float, ...] = ()  # cycled over the views; empty: radius_m for all
    target_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start_azimuth_deg: float = 0.0
    light: str = "rigid"  # "rigid" or "free"
    light_offset_m: tuple[float, float, float] = (0.06, -0.03, 0.0)
    free_light_radius_m: float = 0.45

    @classmethod
    def from_mapping(
        cls, data: Mapping[str, Any] | None, where: str = "sim.trajectory"
    ) -> TrajectoryConfig:
        """Build from a profile section; unknown keys and bad values raise :class:`RigError`."""
        data = dict(data or {})
        reject_unknown_keys(data, (f.name for f in fields(cls)), where)
        for key in ("elevations_deg", "distances_m", "target_m", "light_offset_m"):
            if key in data:
                data[key] = tuple(float(x) for x in data[key])
        conf = cls(**data)
        if conf.views < 1 or conf.radius_m <= 0 or not conf.elevations_deg:
            raise RigError(
                f"{where}: views={conf.views}, radius_m={conf.radius_m}, "
                f"elevations_deg={list(conf.elevations_deg)}",
                "use views >= 1, a positive radius and at least one elevation",
            )
        if any(d <= 0 for d in conf.distances_m):
            raise RigError(
                f"{where}.distances_m = {list(conf.distances_m)}",
                "give positive camera distances in metres, e.g. [0.35, 0.5, 0.65]",
            )
        if conf.light not in ("rigid", "free"):
            raise RigError(f"{where}.light = {conf.light!r}", "use 'rigid' or 'free'")
        if len(conf.target_m) != 3 or len(conf.light_offset_m) != 3:
            raise RigError(f"{where}: target_m and light_offset_m need 3 numbers (metres)")
        return conf


def view_distances(conf: TrajectoryConfig) -> np.ndarray:
    """Camera distance of each view: ``distances_m`` cycled over the views, else ``radius_m``."""
    if not conf.distances_m:
        return np.full(conf.views, conf.radius_m)
    return np.resize(np.asarray(conf.distances_m, dtype=float), conf.views)


def ring_poses(conf: TrajectoryConfig) -> list[Pose]:
    """``conf.views`` poses spread over the elevation rings (as evenly as they divide), each
    ring's azimuths evenly spaced and staggered between rings, all looking at the target from
    :func:`view_distances`."""
    rings = len(conf.elevations_deg)
    counts = [conf.views // rings + (1 if k < conf.views % rings else 0) for k in range(rings)]
    target = np.asarray(conf.target_m, dtype=float)
    distance = iter(view_distances(conf))
    poses: list[Pose] = []
    for k, (elev, n) in enumerate(zip(conf.elevations_deg, counts, strict=True)):
        az = conf.start_azimuth_deg + 360.0 * (np.arange(n) + 0.5 * k) / max(n, 1)
        for a in az:
            poses.append(Pose.look_at(_eye(target, next(distance), a, elev), target))
    return poses


@dataclass(frozen=True)
class PlacementConfig:
    """Free projector placements (the ``sim.projector`` keys besides the optics): ``count``
    placements evenly spread in azimuth, ``views_per_placement`` camera views each."""

    count: int
    views_per_placement: int
    radius_m: float
    elevation_deg: float
    view_spread_deg: float

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], views: int) -> PlacementConfig | None:
        """None when ``placements`` is 0 (the projector rides on the camera plate)."""
        count = int(data.get("placements") or 0)
        if count == 0:
            return None
        per = data.get("views_per_placement")
        per = views // count if per is None else int(per)
        if count < 0 or per < 1 or count * per != views:
            raise RigError(
                f"sim.projector: {count} placements x {per} views per placement does not "
                f"give the {views} views of the trajectory",
                "make views = placements x views_per_placement",
            )
        conf = cls(
            count,
            per,
            float(data.get("placement_radius_m", 0.45)),
            float(data.get("placement_elevation_deg", 15.0)),
            float(data.get("view_spread_deg", 35.0)),
        )
        if conf.radius_m <= 0:
            raise RigError("sim.projector.placement_radius_m must be positive")
        return conf


def _eye(target: np.ndarray, radius: float, azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    a, e = np.deg2rad(azimuth_deg), np.deg2rad(elevation_deg)
    return target + radius * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def placement_poses(
    conf: TrajectoryConfig, placements: PlacementConfig
) -> tuple[list[Pose], list[Pose]]:
    """Camera poses (views of placement k are ``k·M .. k·M + M − 1``) and projector poses.

    Projector k stands at azimuth ``start + 360°·k/K``; its views spread over
    ± ``view_spread_deg`` around it (the side it lights, seen with a baseline to triangulate),
    their elevations cycling through the trajectory's rings; all look at the target.
    """
    target = np.asarray(conf.target_m, dtype=float)
    m = placements.views_per_placement
    spread = placements.view_spread_deg * (np.linspace(-1.0, 1.0, m) if m > 1 else np.ones(1))
    cameras: list[Pose] = []
    projectors: list[Pose] = []
    for k in range(placements.count):
        az = conf.start_azimuth_deg + 360.0 * k / placements.count
        eye = _eye(target, placements.radius_m, az, placements.elevation_deg)
        projectors.append(Pose.look_at(eye, target))
        for j in range(m):
            elev = conf.elevations_deg[j % len(conf.elevations_deg)]
            cameras.append(Pose.look_at(_eye(target, conf.radius_m, az + spread[j], elev), target))
    return cameras, projectors


def light_positions(conf: TrajectoryConfig, poses: Sequence[Pose], seed: int) -> np.ndarray:
    """World light position per view, (N, 3)."""
    if conf.light == "rigid":
        return np.stack([p.light_position(np.asarray(conf.light_offset_m)) for p in poses])
    rng = np.random.default_rng([seed, 7])
    target = np.asarray(conf.target_m, dtype=float)
    out = []
    for p in poses:
        to_cam = p.center - target
        to_cam /= np.linalg.norm(to_cam)
        # Within ~45° of the camera direction so the lit side is the one seen.
        d = to_cam + rng.normal(scale=0.5, size=3)
        out.append(target + conf.free_light_radius_m * d / np.linalg.norm(d))
    return np.stack(out)
