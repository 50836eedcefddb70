"""Rig profiles: one YAML file says which devices, which lights, which capture plan.

Profiles are validated up front so a typo is reported before any device moves: every
error names the file, the key and what is allowed (a ``RigError``). Shipped profiles are
package data of ``profiles`` and load by name (``--profile sim``); any other file loads by
path.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any, Literal

from core.config import bounded, from_mapping, parse_value
from core.errors import RigError
from core.labels import is_reserved
from core.yamlio import read_yaml
from drivers.registry import DRIVERS, GROUND_TRUTH_DRIVERS, check_simulation
from profiles import shipped_profiles
from reconstruct.poses.board import BoardSpec

DEVICE_KINDS = ("light", "camera", "projector", "spectrometer")
# Drivers the capture routes itself; the rest go to ``drivers.registry``.
MAX_VIEWS = 1000  # more than any turntable or handheld session takes
# an hour's exposure and ISO 1,000,000 are beyond any camera the rig drives
CAMERA_SETTING_MAX = {"exposure_s": 3600.0, "iso": 1e6}


@dataclass(frozen=True)
class StructuredLight:
    """Projector patterns per view besides the colour sequence (the plan's illuminations,
    shown full-field by the projector when the rig has no separate light): Gray-code stripes,
    columns and rows, each with its inverse, plus all-white and all-black references."""

    gray_code: bool = True


@dataclass(frozen=True)
class ProjectorPlacements:
    """The projector stands on its own at ``placements`` placements; at each the camera takes
    ``views_per_placement`` views (camera and projector moved alternately), so views lit
    from one placement can be matched through the projector's code."""

    placements: int = bounded(min=1, max=MAX_VIEWS)
    views_per_placement: int = bounded(0, min=0, max=MAX_VIEWS)  # 0: plan.views / placements

    @property
    def count(self) -> int:
        return self.placements

    def of_view(self, view: int) -> int:
        return view // self.views_per_placement


@dataclass(frozen=True)
class Trajectory:
    """Where the views should go, for the person's coverage hint: rings of equal elevation,
    views spread evenly in azimuth on each, and (``distance_factors``, cycled over the views)
    how far to step in or out relative to the usual distance — views at different distances
    are what let the reconstruction tell the light's distance from the reflectance scale."""

    elevations_deg: tuple[float, ...] = bounded((20.0, 45.0), min=-90, max=90, min_items=1)
    azimuth_start_deg: float = bounded(0.0, min=-360, max=360)
    distance_factors: tuple[float, ...] = bounded((), above=0, max=10)

    def distance_factor(self, view: int) -> float | None:
        """Planned distance of ``view`` relative to the usual one; None: no plan."""
        if not self.distance_factors:
            return None
        return self.distance_factors[view % len(self.distance_factors)]

    def view_direction(self, view: int, n_views: int) -> tuple[float, float]:
        """(azimuth, elevation) in degrees of the planned view ``view`` of ``n_views``."""
        rings = len(self.elevations_deg)
        per_ring = math.ceil(n_views / rings)
        ring, slot = divmod(view, per_ring)
        ring = min(ring, rings - 1)
        azimuth = (self.azimuth_start_deg + 360.0 * slot / per_ring) % 360.0
        return azimuth, self.elevations_deg[ring]


@dataclass(frozen=True)
class Plan:
    """``illuminations``: names from the profile's ``illuminations`` (``all``, the default:
    every one, in order)."""

    views: int = bounded(min=1, max=MAX_VIEWS)
    illuminations: tuple[str, ...] = bounded((), min_items=1)
    ambient: bool = False
    structured_light: StructuredLight | None = None
    settle_s: float = bounded(0.0, min=0, max=3600)
    trajectory: Trajectory = field(default_factory=Trajectory)
    projector: ProjectorPlacements | None = None  # None: the projector rides on the plate


@dataclass(frozen=True)
class LightMount:
    """``plate``: light rigidly on the camera plate at ``offset_m`` (camera frame, metres);
    ``free``: a separate light per view. ``diameter_m``: the bulb's emitting diameter (its
    diffuser, about 0.06 for an A19 bulb); None or 0: a point light."""

    type: Literal["plate", "free"] = "plate"
    offset_m: tuple[float, float, float] | None = bounded(None, min=-10, max=10)
    diameter_m: float | None = bounded(None, min=0, max=2)


@dataclass(frozen=True)
class CameraPair:
    """A measured distance between the camera centres of two views (a metric scale for the
    reconstruction)."""

    views: tuple[int, int] = bounded(min=0, max=MAX_VIEWS)
    metres: float = bounded(above=0, max=1000)

    def as_dict(self) -> dict[str, Any]:
        return {"views": list(self.views), "metres": self.metres}


@dataclass(frozen=True)
class KnownDistances:
    """Lengths measured on the rig: the light's offset from the camera, a scale bar in the
    scene, distances between camera centres."""

    light_offset_m: float | None = bounded(None, above=0, max=100)
    scale_bar_m: float | None = bounded(None, above=0, max=100)
    camera_pairs: tuple[CameraPair, ...] = ()


@dataclass(frozen=True)
class CalibrationChoice:
    """Which calibration store and which of its entries this rig uses."""

    camera: str
    store: str = "default"  # a directory, or "default" for the built-in store
    lights: Mapping[str, str] = field(default_factory=dict)  # illumination -> light SPD entry
    flat_field: str | None = None  # the store's flat-field entry decode divides by (None: none)


@dataclass(frozen=True)
class Devices:
    """One section per device kind, each naming its ``driver`` (its other keys are the
    driver's own, checked when it opens)."""

    light: dict[str, Any] | None = None
    camera: dict[str, Any] | None = None
    projector: dict[str, Any] | None = None
    spectrometer: dict[str, Any] | None = None


@dataclass(frozen=True)
class ProfileFile:
    """A profile YAML file as written; :func:`parse_profile` checks what spans sections."""

    devices: Devices
    illuminations: dict[str, dict[str, float]] = bounded(min=0, max=1, min_items=1)
    plan: Plan = bounded()
    name: str | None = None
    description: str | None = None
    camera_settings: dict[str, Any] = field(default_factory=dict)
    light_mount: LightMount = field(default_factory=LightMount)
    calibration: CalibrationChoice | None = None
    known_distances: KnownDistances = field(default_factory=KnownDistances)
    poses: Literal["estimate", "known"] = "estimate"
    sim: dict[str, Any] = field(default_factory=dict)
    board: dict[str, Any] | None = None


@dataclass(frozen=True)
class Profile:
    name: str
    source: str  # where it was loaded from (file path)
    data: Mapping[str, Any]  # the validated YAML as a plain mapping, for the session snapshot
    devices: Mapping[str, Mapping[str, Any]]
    illuminations: Mapping[str, Mapping[str, float]]
    plan: Plan
    light_mount: LightMount
    camera_settings: Mapping[str, Any]
    calibration: CalibrationChoice | None
    known_distances: Mapping[str, float]  # light_offset_m, scale_bar_m
    camera_pairs: tuple[CameraPair, ...]  # measured distances between camera centres
    poses: str
    sim: Mapping[str, Any]
    board: BoardSpec | None = None  # the printed marker board under the object

    def device(self, kind: str) -> Mapping[str, Any] | None:
        return self.devices.get(kind)


def resolve_profile(name_or_path: str | Path) -> Path:
    """A shipped profile name (``sim``) or a path to a YAML file."""
    text = str(name_or_path)
    path = Path(text).expanduser()
    if path.suffix in (".yaml", ".yml") or path.exists() or "/" in text:
        if not path.is_file():
            raise RigError(
                f"profile file {path} does not exist",
                f"give a YAML file or a shipped profile: {', '.join(shipped_profiles())}",
            )
        return path
    shipped = resources.files("profiles") / f"{text}.yaml"
    if not shipped.is_file():
        raise RigError(
            f"no shipped profile named '{text}'",
            f"use one of {', '.join(shipped_profiles())} or give a path to a YAML file",
        )
    return Path(str(shipped))


def load_profile(name_or_path: str | Path) -> Profile:
    """Read and validate a profile by shipped name or path."""
    path = resolve_profile(name_or_path)
    data = read_yaml(
        path, "profile", "fix the YAML syntax (indentation, colons, quotes, repeated keys)"
    )
    return parse_profile(data, str(path))


def parse_profile(data: Any, source: str) -> Profile:
    """Validate a profile mapping; ``source`` names it in every error."""
    if data is None:
        raise RigError(f"{source} is empty", "write a profile; see profiles/sim.yaml")
    top = from_mapping(ProfileFile, _all_illuminations(data), source)
    devices = _devices(top.devices, source)
    _check_illuminations(top.illuminations, source)
    plan = _plan(top.plan, top.illuminations, devices, source)
    _check_light_mount(top.light_mount, source)
    for key, highest in CAMERA_SETTING_MAX.items():
        if key in top.camera_settings:
            parse_value(top.camera_settings[key], float, source, f"camera_settings.{key}",
                        {"above": 0, "max": highest})
    _check_camera_pairs(top.known_distances.camera_pairs, plan.views, source)
    if top.poses == "known" and not any(
        d.get("driver") in GROUND_TRUTH_DRIVERS for d in devices.values()
    ):
        raise _fail(source, "poses", "is 'known' but no device is simulated",
                    "'estimate' for a real rig (known poses come only from the sim)")
    check_simulation(top.sim, source)  # now: the simulator reads it only when it opens
    calibration = top.calibration
    if calibration is not None:
        unnamed = {n: n for n in plan.illuminations if n not in calibration.lights}
        calibration = replace(calibration, lights={**calibration.lights, **unnamed})
    name = Path(source).stem if top.name is None else top.name
    if not name.strip():
        raise _fail(source, "name", "is empty", "a name for the rig")
    distances = top.known_distances
    return Profile(
        name=name,
        source=source,
        data=copy.deepcopy(dict(data)),
        devices=devices,
        illuminations=top.illuminations,
        plan=plan,
        light_mount=top.light_mount,
        camera_settings=top.camera_settings,
        calibration=calibration,
        known_distances={
            k: v for k, v in (("light_offset_m", distances.light_offset_m),
                              ("scale_bar_m", distances.scale_bar_m)) if v is not None
        },
        camera_pairs=distances.camera_pairs,
        poses=top.poses,
        sim=top.sim,
        board=None if top.board is None else BoardSpec.from_dict(top.board, source),
    )


def _fail(source: str, key: str, problem: str, allowed: str) -> RigError:
    return RigError(f"{source}: key '{key}' {problem}", f"allowed: {allowed}")


def _all_illuminations(data: Any) -> Any:
    """``data`` with ``plan.illuminations: all`` (or none) spelt out as every defined name."""
    if not isinstance(data, Mapping) or not isinstance(data.get("plan"), Mapping):
        return data
    chosen = data["plan"].get("illuminations", "all")
    if chosen != "all" or not isinstance(data.get("illuminations"), Mapping):
        return data
    return {**data, "plan": {**data["plan"], "illuminations": list(data["illuminations"])}}


def _devices(section: Devices, source: str) -> dict[str, dict[str, Any]]:
    devices = {kind: getattr(section, kind) for kind in DEVICE_KINDS}
    devices = {kind: spec for kind, spec in devices.items() if spec is not None}
    for kind, spec in devices.items():
        key = f"devices.{kind}.driver"
        if "driver" not in spec:
            raise _fail(source, key, "is missing",
                        f"a driver name, e.g. {', '.join(known_drivers(kind)[:3])}")
        driver = parse_value(spec["driver"], str, source, key)
        known = known_drivers(kind)
        if (known and driver not in known) or not driver.strip():
            raise _fail(source, key, f"is '{driver}'", ", ".join(known) or "a driver name")
        if "transport" in spec:
            parse_value(spec["transport"], dict[str, Any], source, f"devices.{kind}.transport")
    if "camera" not in devices:
        raise _fail(source, "devices.camera", "is missing", "a camera section with a driver")
    if "light" not in devices and "projector" not in devices:
        raise _fail(source, "devices.light", "is missing (and there is no projector)",
                    "a light or a projector section with a driver")
    return devices


def _check_illuminations(illuminations: Mapping[str, Mapping[str, float]], source: str) -> None:
    for name, levels in illuminations.items():
        key = f"illuminations.{name}"
        if (
            is_reserved(name)
            or not name.replace("-", "_").isidentifier()
        ):
            raise _fail(source, key, "is not a usable name",
                        "letters, digits, '_' or '-'; 'ambient', 'white', 'black' and 'gray-...' "
                        "name the ambient and structured-light frames")
        if not levels:
            raise _fail(source, key, "has no channel levels", "channel: level in [0, 1]")


def _plan(
    plan: Plan, illuminations: Mapping[str, Any], devices: Mapping[str, Any], source: str
) -> Plan:
    """``plan`` checked against the rest of the profile, with its projector placements'
    ``views_per_placement`` filled in."""
    for name in plan.illuminations:
        if name not in illuminations:
            raise _fail(source, "plan.illuminations", f"names '{name}', which is not defined",
                        ", ".join(illuminations))
    if len(set(plan.illuminations)) != len(plan.illuminations):
        raise _fail(source, "plan.illuminations", "repeats a name", "each illumination once")
    if plan.structured_light is not None and "projector" not in devices:
        raise _fail(source, "plan.structured_light", "needs a projector",
                    "a devices.projector section, or remove plan.structured_light")
    placements = plan.projector
    if placements is None:
        return plan
    if "projector" not in devices:
        raise _fail(source, "plan.projector", "needs a projector", "a devices.projector section")
    per = placements.views_per_placement or plan.views // placements.placements
    if per < 1 or per * placements.placements != plan.views:
        raise _fail(
            source,
            "plan.projector.views_per_placement",
            f"is {per}: {placements.placements} placements x {per} views is not "
            f"plan.views = {plan.views}",
            "a whole number with placements x views_per_placement = plan.views",
        )
    return replace(plan, projector=replace(placements, views_per_placement=per))


def _check_light_mount(mount: LightMount, source: str) -> None:
    if mount.type == "free" and mount.offset_m is not None:
        raise _fail(source, "light_mount.offset_m", "is set for a free light",
                    "an offset only with type: plate")


def _check_camera_pairs(pairs: tuple[CameraPair, ...], n_views: int, source: str) -> None:
    for i, pair in enumerate(pairs):
        if max(pair.views) >= n_views or pair.views[0] == pair.views[1]:
            raise _fail(source, f"known_distances.camera_pairs[{i}].views",
                        f"is {list(pair.views)}", f"two different views in 0..{n_views - 1}")


def known_drivers(kind: str) -> tuple[str, ...]:
    """Driver names accepted for ``kind`` (the registry's)."""
    return DRIVERS[kind]

