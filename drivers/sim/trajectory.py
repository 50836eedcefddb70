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

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from core.config import bounded
from core.errors import RigError
from reconstruct.model.camera import Pose

MAX_VIEWS = 1000  # more than any capture takes; the sim renders every one


@dataclass(frozen=True)
class ProjectorConfig:
    """The ``sim.projector`` section: the projector's optics, its offset on the camera plate,
    and (``placements`` > 0) free placements instead, ``views_per_placement`` camera views each
    (default: views / placements)."""

    width: int = bounded(800, min=16, max=16_384)
    height: int = bounded(600, min=16, max=16_384)
    focal_px: float = bounded(1000.0, above=0, max=1e6)
    offset_m: tuple[float, float, float] = bounded((-0.08, 0.0, 0.0), min=-10, max=10)
    placements: int = bounded(0, min=0, max=MAX_VIEWS)
    views_per_placement: int | None = bounded(None, min=1, max=MAX_VIEWS)
    placement_radius_m: float = bounded(0.45, above=0, max=100)
    placement_elevation_deg: float = bounded(15.0, min=-90, max=90)
    view_spread_deg: float = bounded(35.0, min=0, max=180)


@dataclass(frozen=True)
class TrajectoryConfig:
    """Ring trajectory settings (the ``trajectory`` section of a sim profile)."""

    views: int = bounded(40, min=1, max=MAX_VIEWS)
    elevations_deg: tuple[float, ...] = bounded((20.0, 45.0), min=-90, max=90, min_items=1)
    radius_m: float = bounded(0.5, above=0, max=100)
    # cycled over the views; empty: radius_m for all
    distances_m: tuple[float, ...] = bounded((), above=0, max=100)
    target_m: tuple[float, float, float] = bounded((0.0, 0.0, 0.0), min=-100, max=100)
    start_azimuth_deg: float = bounded(0.0, min=-360, max=360)
    light: Literal["rigid", "free"] = "rigid"
    light_offset_m: tuple[float, float, float] = bounded((0.06, -0.03, 0.0), min=-10, max=10)
    free_light_radius_m: float = bounded(0.45, above=0, max=100)


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
    def for_views(cls, projector: ProjectorConfig, views: int) -> PlacementConfig | None:
        """None when ``placements`` is 0 (the projector rides on the camera plate)."""
        count = projector.placements
        if count == 0:
            return None
        per = projector.views_per_placement or views // count
        if per < 1 or count * per != views:
            raise RigError(
                f"sim.projector: {count} placements x {per} views per placement does not "
                f"give the {views} views of the trajectory",
                "make views = placements x views_per_placement",
            )
        return cls(
            count,
            per,
            projector.placement_radius_m,
            projector.placement_elevation_deg,
            projector.view_spread_deg,
        )


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
