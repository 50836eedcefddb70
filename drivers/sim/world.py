"""The simulated world behind ``driver: sim``: one :class:`SimRig` per opened device set,
configured from the profile's ``sim`` section completed by the rest of the profile, so the
virtual rig matches the plan."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from drivers.device_set import DeviceSet
from drivers.sim.rig import SimRig
from drivers.sim.trajectory import TrajectoryConfig
from reconstruct.poses.board import BoardSpec, board_texture

WORLD_KEY = "sim"
BOARD_PX_PER_M = 6000.0  # texture resolution: 0.17 mm texels, finer than a sub-pixel
PAPER_REFLECTANCE = 0.85
INK_REFLECTANCE = 0.04


def shared_rig(devices: DeviceSet) -> SimRig:
    """The set's simulated rig, created on first use."""
    rig = devices.shared.get(WORLD_KEY)
    if rig is None:
        rig = SimRig(
            world_config(devices),
            devices.seed,
            reference_camera=dict(devices.simulation.get("camera") or {}),
        )
        devices.shared[WORLD_KEY] = rig
    return rig


def world_config(devices: DeviceSet) -> dict[str, Any]:
    """The ``sim`` section completed from the plan: as many views, the plate offset (or a free
    light) and the bulb's size, the elevations and the distances the person is asked to step to, the
    illuminations, the camera settings, the projector placements and the board (the ground
    plane the object stands on)."""
    config = copy.deepcopy(dict(devices.simulation))
    if devices.views is not None:
        config["views"] = devices.views
    trajectory = dict(config.get("trajectory") or {})
    if devices.elevations_deg:
        trajectory.setdefault("elevations_deg", list(devices.elevations_deg))
    factors = devices.distance_factors
    if factors and "distances_m" not in trajectory:  # the sim steps in and out as planned
        radius = float(trajectory.get("radius_m", TrajectoryConfig.radius_m))
        trajectory["distances_m"] = [radius * f for f in factors]
    if devices.free_light:
        trajectory["light"] = "free"
    elif devices.light_offset_m is not None:
        config["light_offset_m"] = list(devices.light_offset_m)
    config["trajectory"] = trajectory
    if devices.light_diameter_m:  # the simulated bulb is the size the profile gives it
        config.setdefault("light_diameter_m", devices.light_diameter_m)
    config.setdefault("illuminations", {k: dict(v) for k, v in devices.illuminations.items()})
    camera = dict(config.get("camera") or {})
    for key in ("exposure_s", "iso"):
        if key in devices.camera_settings:
            camera.setdefault(key, devices.camera_settings[key])
    config["camera"] = camera
    if devices.projector_placements is not None:
        projector = dict(config.get("projector") or {})
        projector["placements"] = devices.projector_placements
        projector["views_per_placement"] = devices.views_per_placement
        config["projector"] = projector
    if devices.board is not None and "ground" not in config:
        config["ground"] = board_ground(devices.board)
    return config


def board_ground(board: BoardSpec) -> dict[str, Any]:
    """The ground plane for a printed board: its paper/ink texture in the board's world frame
    (z = 0, origin at the board centre), white paper and near-black ink."""
    texture, extent = board_texture(board, BOARD_PX_PER_M)
    return {
        "texture": texture.astype(np.float32),
        "extent": list(extent),
        "paper": PAPER_REFLECTANCE,
        "ink": INK_REFLECTANCE,
    }
