"""What the devices opened from one profile share: the rig the profile plans (some drivers,
like the simulator, build their world from it) and the state those drivers share."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass
class DeviceSet:
    """One opening of a profile's devices; ``shared`` holds a driver's state for the set (the
    simulator's world is created once here and every ``driver: sim`` device is part of it)."""

    seed: int = 0
    views: int | None = None  # None: as many as the driver likes
    elevations_deg: tuple[float, ...] = ()
    distance_factors: tuple[float, ...] = ()
    free_light: bool = False  # the person holds the light at a new place per view
    light_offset_m: tuple[float, ...] | None = None  # the light on the camera plate
    light_diameter_m: float | None = None  # the bulb's size (None: a point light)
    illuminations: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    camera_settings: Mapping[str, Any] = field(default_factory=dict)
    projector_placements: int | None = None  # None: the projector rides on the plate
    views_per_placement: int | None = None
    board: Any = None  # reconstruct.poses.board.BoardSpec the object stands on
    simulation: Mapping[str, Any] = field(default_factory=dict)  # the profile's `sim` section
    shared: dict[str, Any] = field(default_factory=dict)
