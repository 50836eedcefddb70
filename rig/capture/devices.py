"""Open the devices a profile names: ``driver: sim`` goes to one shared simulated rig,
``driver: manual`` to a light the person switches by hand, everything else to
``drivers.registry``. Device failures are turned into ``RigError`` naming the device."""

from __future__ import annotations

import copy
import importlib
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from core.errors import RigError
from drivers.protocols import Camera, LightSource, Projector, Spectrometer
from reconstruct.poses.board import BoardSpec, board_texture
from rig.profile import Profile

Ask = Callable[[str], str]


@dataclass
class RigDevices:
    """The opened devices of one capture run."""

    camera: Camera
    light: LightSource | None = None
    projector: Projector | None = None
    spectrometer: Spectrometer | None = None
    sim: Any | None = None  # drivers.sim.SimRig when any device is simulated
    names: dict[str, str] = field(default_factory=dict)  # kind -> driver name

    def goto_view(self, view: int) -> None:
        """The sim moves its camera itself; a real rig is moved by the person."""
        if self.sim is not None:
            self.sim.goto_view(view)

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for kind in ("camera", "light", "projector", "spectrometer"):
            device = getattr(self, kind)
            if device is not None:
                with device_errors(kind, self.names.get(kind, "?"), "describe"):
                    out[kind] = {"driver": self.names.get(kind, "?"), **device.describe()}
        return out

    def close(self) -> None:
        for kind in ("light", "projector", "camera", "spectrometer"):
            device = getattr(self, kind)
            if device is not None:
                try:
                    device.close()
                except Exception:  # closing must not mask the real error or lose the session
                    continue


@contextmanager
def device_errors(kind: str, driver: str, action: str) -> Iterator[None]:
    """Re-raise anything a device throws as a RigError naming it (RigErrors pass through)."""
    try:
        yield
    except RigError:
        raise
    except KeyboardInterrupt:
        raise
    except Exception as exc:
        raise RigError(
            f"{kind} ({driver}) failed to {action}: {type(exc).__name__}: {exc}",
            "check the device's cable/power and the profile's transport",
        ) from exc


def open_sim(config: Mapping[str, Any], seed: int) -> Any:
    try:
        module = importlib.import_module("drivers.sim")
    except ImportError as exc:
        raise RigError(
            "the simulated rig (drivers.sim) is not available",
            f"install spectral-rig completely ({exc})",
        ) from exc
    return module.SimRig(config, seed=seed)


def sim_config(profile: Profile) -> dict[str, Any]:
    """The profile's ``sim`` section completed from the rest of the profile, so the virtual
    rig matches the plan: as many views, the plate offset (or a free light), the elevations
    and the distances the person is asked to step to, the illuminations, the camera settings,
    the projector placements and the board (the ground plane the object stands on)."""
    config = copy.deepcopy(dict(profile.sim))
    config["views"] = profile.plan.views
    trajectory = dict(config.get("trajectory") or {})
    trajectory.setdefault("elevations_deg", list(profile.plan.trajectory.elevations_deg))
    factors = profile.plan.trajectory.distance_factors
    if factors and "distances_m" not in trajectory:  # the sim steps in and out as planned
        from drivers.sim.trajectory import TrajectoryConfig  # the sim loads only when used

        radius = float(trajectory.get("radius_m", TrajectoryConfig.radius_m))
        trajectory["distances_m"] = [radius * f for f in factors]
    if profile.light_mount.type == "free":
        trajectory["light"] = "free"
    elif profile.light_mount.offset_m is not None:
        config["light_offset_m"] = list(profile.light_mount.offset_m)
    config["trajectory"] = trajectory
    config.setdefault("illuminations", {k: dict(v) for k, v in profile.illuminations.items()})
    camera = dict(config.get("camera") or {})
    for key in ("exposure_s", "iso"):
        if key in profile.camera_settings:
            camera.setdefault(key, profile.camera_settings[key])
    config["camera"] = camera
    placements = profile.plan.projector
    if placements is not None:
        projector = dict(config.get("projector") or {})
        projector["placements"] = placements.count
        projector["views_per_placement"] = placements.views_per_placement
        config["projector"] = projector
    if profile.board is not None and "ground" not in config:
        config["ground"] = board_ground(profile.board)
    return config


BOARD_PX_PER_M = 6000.0  # texture resolution: 0.17 mm texels, finer than a sub-pixel
PAPER_REFLECTANCE = 0.85
INK_REFLECTANCE = 0.04


def board_ground(board: BoardSpec) -> dict[str, Any]:
    """The sim's ground plane for a printed board: its paper/ink texture in the board's
    world frame (z = 0, origin at the board centre), white paper and near-black ink."""
    texture, extent = board_texture(board, BOARD_PX_PER_M)
    return {
        "texture": texture.astype(np.float32),
        "extent": list(extent),
        "paper": PAPER_REFLECTANCE,
        "ink": INK_REFLECTANCE,
    }


def open_devices(
    profile: Profile,
    seed: int,
    ask: Ask | None,
    kinds: tuple[str, ...] = ("camera", "light", "projector"),
) -> RigDevices:
    """Open every device of ``kinds`` the profile names (the spectrometer only for the
    calibration wizard)."""
    sim = (
        open_sim(sim_config(profile), seed)
        if any((profile.device(k) or {}).get("driver") == "sim" for k in kinds)
        else None
    )
    opened: dict[str, Any] = {}
    names: dict[str, str] = {}
    try:
        for kind in kinds:
            spec = profile.device(kind)
            if spec is None:
                continue
            driver = str(spec["driver"])
            names[kind] = driver
            if driver == "sim":
                device = getattr(sim, kind, None)
                if device is None:
                    raise RigError(
                        f"the simulated rig has no {kind}",
                        f"remove devices.{kind} from {profile.source}",
                    )
            elif driver == "manual" and kind == "light":
                device = open_manual_light(spec, profile, ask)
            else:
                device = _open_registry(kind, spec, profile)
            opened[kind] = device
    except BaseException:
        for device in opened.values():
            device.close()
        raise
    if "camera" not in opened:
        raise RigError(f"{profile.source} names no camera", "add a devices.camera section")
    return RigDevices(
        camera=opened["camera"],
        light=opened.get("light"),
        projector=opened.get("projector"),
        spectrometer=opened.get("spectrometer"),
        sim=sim,
        names=names,
    )


def open_manual_light(spec: Mapping[str, Any], profile: Profile, ask: Ask | None) -> Any:
    """The person switches the light when asked; impossible without a person (--yes)."""
    if ask is None:
        raise RigError(
            f"{profile.source}: the light is 'manual' but the capture runs with --yes",
            "drop --yes so the person can switch the light when asked",
        )
    from drivers.lights.base import DEFAULT_CHANNELS
    from drivers.lights.manual import ManualLight

    used = {c for levels in profile.illuminations.values() for c in levels}
    channels = spec.get("channels") or [*DEFAULT_CHANNELS, *sorted(used - set(DEFAULT_CHANNELS))]
    return ManualLight(channels, profile.illuminations, float(spec.get("settle_s", 0.0)), ask)


def _open_registry(kind: str, spec: Mapping[str, Any], profile: Profile) -> Any:
    try:
        registry = importlib.import_module("drivers.registry")
    except ImportError as exc:
        raise RigError(
            f"real {kind} drivers (drivers.registry) are not available",
            "use a profile with driver: sim, or install spectral-rig completely",
        ) from exc
    spec = dict(spec)
    if kind == "camera" and profile.camera_settings:
        spec["settings"] = {**dict(profile.camera_settings), **spec.get("settings", {})}
    if kind == "light":
        spec.setdefault("illuminations", {k: dict(v) for k, v in profile.illuminations.items()})
    opener = getattr(registry, f"open_{kind}")
    with device_errors(kind, str(spec["driver"]), "open"):
        return opener(spec)
