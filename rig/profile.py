"""Rig profiles: one YAML file says which devices, which lights, which capture plan.

Profiles are validated up front so a typo is reported before any device moves: every
error names the file, the key and what is allowed (a ``RigError``). Shipped profiles are
package data of ``profiles`` and load by name (``--profile sim``); any other file loads by
path.
"""

from __future__ import annotations

import copy
import difflib
import importlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from core.errors import RigError
from core.labels import is_reserved
from core.yamlio import read_yaml
from drivers.registry import GROUND_TRUTH_DRIVERS
from reconstruct.poses.board import BoardSpec

DEVICE_KINDS = ("light", "camera", "projector", "spectrometer")
# Drivers the capture routes itself; the rest go to ``drivers.registry``.
LOCAL_DRIVERS: dict[str, tuple[str, ...]] = {
    "light": ("manual",),
    "camera": (),
    "projector": (),
    "spectrometer": (),
}
MOUNT_TYPES = ("plate", "free")
POSE_MODES = ("estimate", "known")
TOP_KEYS = (
    "name",
    "description",
    "devices",
    "camera_settings",
    "light_mount",
    "illuminations",
    "plan",
    "calibration",
    "known_distances",
    "poses",
    "sim",
    "board",
)
PLAN_KEYS = (
    "views",
    "illuminations",
    "ambient",
    "structured_light",
    "settle_s",
    "trajectory",
    "projector",
)
PROJECTOR_PLAN_KEYS = ("placements", "views_per_placement")
TRAJECTORY_KEYS = ("elevations_deg", "azimuth_start_deg", "distance_factors")
STRUCTURED_KEYS = ("gray_code",)
CALIBRATION_KEYS = ("store", "camera", "lights")
DISTANCE_KEYS = ("light_offset_m", "scale_bar_m", "camera_pairs")
MOUNT_KEYS = ("type", "offset_m")


@dataclass(frozen=True)
class StructuredLight:
    """Projector patterns per view besides the colour sequence (the plan's illuminations,
    shown full-field by the projector when the rig has no separate light): Gray-code stripes,
    columns and rows, each with its inverse, plus all-white and all-black references."""

    gray_code: bool


@dataclass(frozen=True)
class ProjectorPlacements:
    """The projector stands on its own at ``count`` placements; at each the camera takes
    ``views_per_placement`` views (camera and projector moved alternately), so views lit
    from one placement can be matched through the projector's code."""

    count: int
    views_per_placement: int

    def of_view(self, view: int) -> int:
        return view // self.views_per_placement


@dataclass(frozen=True)
class Trajectory:
    """Where the views should go, for the person's coverage hint: rings of equal elevation,
    views spread evenly in azimuth on each, and (``distance_factors``, cycled over the views)
    how far to step in or out relative to the usual distance — views at different distances
    are what let the reconstruction tell the light's distance from the reflectance scale."""

    elevations_deg: tuple[float, ...] = (20.0, 45.0)
    azimuth_start_deg: float = 0.0
    distance_factors: tuple[float, ...] = ()

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
    views: int
    illuminations: tuple[str, ...]
    ambient: bool = False
    structured_light: StructuredLight | None = None
    settle_s: float = 0.0
    trajectory: Trajectory = field(default_factory=Trajectory)
    projector: ProjectorPlacements | None = None  # None: the projector rides on the plate


@dataclass(frozen=True)
class LightMount:
    """``plate``: light rigidly on the camera plate at ``offset_m`` (camera frame, metres);
    ``free``: a separate light per view."""

    type: str
    offset_m: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class CameraPair:
    """A measured distance between the camera centres of two views (a metric scale for the
    reconstruction)."""

    view_a: int
    view_b: int
    metres: float

    def as_dict(self) -> dict[str, Any]:
        return {"views": [self.view_a, self.view_b], "metres": self.metres}


@dataclass(frozen=True)
class CalibrationChoice:
    """Which calibration store and which of its entries this rig uses."""

    store: str  # a directory, or "default" for the built-in store
    camera: str
    lights: Mapping[str, str]  # illumination name -> light SPD entry in the store


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


def shipped_profiles() -> list[str]:
    """Names of the profiles shipped as package data."""
    root = resources.files("profiles")
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".yaml"))


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
    return _Validator(source).profile(data)


class _Validator:
    """Checks one profile; every error says file, key and what is allowed."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, problem: str, allowed: str) -> RigError:
        return RigError(f"{self.source}: key '{key}' {problem}", f"allowed: {allowed}")

    def mapping(self, value: Any, key: str, allowed_keys: tuple[str, ...] | None) -> dict[str, Any]:
        if not isinstance(value, Mapping):
            raise self.fail(
                key,
                f"must be a mapping, got {_show(value)}",
                f"a mapping with keys {', '.join(allowed_keys or ('...',))}",
            )
        if allowed_keys is not None:
            for name in value:
                if name not in allowed_keys:
                    close = difflib.get_close_matches(str(name), allowed_keys, n=1)
                    raise self.fail(
                        f"{key}.{name}" if key else str(name),
                        "is not known" + (f" (did you mean '{close[0]}'?)" if close else ""),
                        ", ".join(allowed_keys),
                    )
        return dict(value)

    def number(
        self, value: Any, key: str, *, low: float | None = None, positive: bool = False
    ) -> float:
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
        ):
            raise self.fail(key, f"must be a number, got {_show(value)}", "a finite number")
        if positive and value <= 0:
            raise self.fail(key, f"must be positive, got {value}", "a number > 0")
        if low is not None and value < low:
            raise self.fail(key, f"must be at least {low}, got {value}", f"a number >= {low}")
        return float(value)

    def boolean(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.fail(key, f"must be true or false, got {_show(value)}", "true, false")
        return value

    def choice(self, value: Any, key: str, options: tuple[str, ...]) -> str:
        if value not in options:
            raise self.fail(key, f"is {_show(value)}", ", ".join(options))
        return str(value)

    def string(self, value: Any, key: str) -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.fail(key, f"must be a non-empty string, got {_show(value)}", "a string")
        return value

    def profile(self, data: Any) -> Profile:
        if data is None:
            raise RigError(f"{self.source} is empty", "write a profile; see profiles/sim.yaml")
        top = self.mapping(data, "", TOP_KEYS)
        for key in ("devices", "illuminations", "plan"):
            if key not in top:
                raise self.fail(key, "is missing", "see profiles/sim.yaml for a complete profile")
        devices = self.devices(top["devices"])
        illuminations = self.illuminations(top["illuminations"], devices)
        plan = self.plan(top["plan"], illuminations, devices)
        mount = self.light_mount(top.get("light_mount", {"type": "plate"}))
        settings = self.mapping(top.get("camera_settings", {}), "camera_settings", None)
        for key in ("exposure_s", "iso"):
            if key in settings:
                self.number(settings[key], f"camera_settings.{key}", positive=True)
        calibration = self.calibration(top.get("calibration"), plan)
        distances = self.mapping(top.get("known_distances", {}), "known_distances", DISTANCE_KEYS)
        pairs = self.camera_pairs(distances.pop("camera_pairs", []), plan.views)
        known = {
            k: self.number(v, f"known_distances.{k}", positive=True) for k, v in distances.items()
        }
        poses = self.choice(top.get("poses", "estimate"), "poses", POSE_MODES)
        sim = self.mapping(top.get("sim", {}), "sim", None)
        self.sim_trajectory(sim.get("trajectory"))
        if poses == "known" and not any(
            d.get("driver") in GROUND_TRUTH_DRIVERS for d in devices.values()
        ):
            raise self.fail(
                "poses",
                "is 'known' but no device knows the true poses",
                "'estimate' for a real rig (known poses come only from the simulator)",
            )
        board = None
        if top.get("board") is not None:
            board = BoardSpec.from_dict(self.mapping(top["board"], "board", None), self.source)
        name = top.get("name", Path(self.source).stem)
        return Profile(
            name=self.string(name, "name"),
            source=self.source,
            data=copy.deepcopy(top),
            devices=devices,
            illuminations=illuminations,
            plan=plan,
            light_mount=mount,
            camera_settings=settings,
            calibration=calibration,
            known_distances=known,
            camera_pairs=pairs,
            poses=poses,
            sim=sim,
            board=board,
        )

    def devices(self, value: Any) -> dict[str, dict[str, Any]]:
        section = self.mapping(value, "devices", DEVICE_KINDS)
        devices: dict[str, dict[str, Any]] = {}
        for kind, spec in section.items():
            if spec is None:
                continue
            spec = self.mapping(spec, f"devices.{kind}", None)
            if "driver" not in spec:
                raise self.fail(
                    f"devices.{kind}.driver",
                    "is missing",
                    f"a driver name, e.g. {', '.join(known_drivers(kind)[:3])}",
                )
            driver = self.string(spec["driver"], f"devices.{kind}.driver")
            known = known_drivers(kind)
            if known and driver not in known:
                raise self.fail(f"devices.{kind}.driver", f"is '{driver}'", ", ".join(known))
            if "transport" in spec:
                self.mapping(spec["transport"], f"devices.{kind}.transport", None)
            devices[kind] = spec
        if "camera" not in devices:
            raise self.fail("devices.camera", "is missing", "a camera section with a driver")
        if "light" not in devices and "projector" not in devices:
            raise self.fail(
                "devices.light",
                "is missing (and there is no projector)",
                "a light or a projector section with a driver",
            )
        return devices

    def illuminations(self, value: Any, devices: Mapping[str, Any]) -> dict[str, dict[str, float]]:
        section = self.mapping(value, "illuminations", None)
        if not section:
            raise self.fail("illuminations", "is empty", "at least one named illumination")
        out: dict[str, dict[str, float]] = {}
        for name, levels in section.items():
            key = f"illuminations.{name}"
            if (
                not isinstance(name, str)
                or is_reserved(name)
                or not name.replace("-", "_").isidentifier()
            ):
                raise self.fail(
                    key,
                    "is not a usable name",
                    "letters, digits, '_' or '-'; 'ambient', 'white', 'black' and 'gray-...' "
                    "name the ambient and structured-light frames",
                )
            levels = self.mapping(levels, key, None)
            if not levels:
                raise self.fail(key, "has no channel levels", "channel: level in [0, 1]")
            parsed = {}
            for channel, level in levels.items():
                number = self.number(level, f"{key}.{channel}", low=0.0)
                if number > 1.0:
                    raise self.fail(f"{key}.{channel}", f"is {number}", "a level in [0, 1]")
                parsed[str(channel)] = number
            out[name] = parsed
        return out

    def plan(
        self, value: Any, illuminations: Mapping[str, Any], devices: Mapping[str, Any]
    ) -> Plan:
        section = self.mapping(value, "plan", PLAN_KEYS)
        if "views" not in section:
            raise self.fail("plan.views", "is missing", "a positive whole number of views")
        views = section["views"]
        if isinstance(views, bool) or not isinstance(views, int) or views < 1:
            raise self.fail("plan.views", f"is {_show(views)}", "a positive whole number")
        chosen = section.get("illuminations", "all")
        if chosen == "all":
            chosen = list(illuminations)
        if not isinstance(chosen, list) or not chosen:
            raise self.fail(
                "plan.illuminations",
                f"is {_show(chosen)}",
                "'all' or a list of names from 'illuminations'",
            )
        for name in chosen:
            if name not in illuminations:
                raise self.fail(
                    "plan.illuminations",
                    f"names '{name}', which is not defined",
                    ", ".join(illuminations),
                )
        if len(set(chosen)) != len(chosen):
            raise self.fail("plan.illuminations", "repeats a name", "each illumination once")
        ambient = self.boolean(section.get("ambient", False), "plan.ambient")
        settle = self.number(section.get("settle_s", 0.0), "plan.settle_s", low=0.0)
        structured = None
        if section.get("structured_light") is not None:
            if "projector" not in devices:
                raise self.fail(
                    "plan.structured_light",
                    "needs a projector",
                    "a devices.projector section, or remove plan.structured_light",
                )
            sl = self.mapping(section["structured_light"], "plan.structured_light", STRUCTURED_KEYS)
            structured = StructuredLight(
                self.boolean(sl.get("gray_code", True), "plan.structured_light.gray_code")
            )
        trajectory = Trajectory()
        if "trajectory" in section:
            tr = self.mapping(section["trajectory"], "plan.trajectory", TRAJECTORY_KEYS)
            elevations = tr.get("elevations_deg", list(trajectory.elevations_deg))
            if not isinstance(elevations, list) or not elevations:
                raise self.fail(
                    "plan.trajectory.elevations_deg",
                    f"is {_show(elevations)}",
                    "a non-empty list of elevations in degrees",
                )
            factors = tr.get("distance_factors", [])
            key = "plan.trajectory.distance_factors"
            if not isinstance(factors, list):
                raise self.fail(
                    key, f"is {_show(factors)}", "a list of positive factors, e.g. [0.7, 1.0, 1.3]"
                )
            trajectory = Trajectory(
                self.elevations(elevations, "plan.trajectory.elevations_deg"),
                self.number(tr.get("azimuth_start_deg", 0.0), "plan.trajectory.azimuth_start_deg"),
                tuple(self.number(f, key, positive=True) for f in factors),
            )
        placements = None
        if section.get("projector") is not None:
            placements = self.projector_placements(section["projector"], views, devices)
        return Plan(views, tuple(chosen), ambient, structured, settle, trajectory, placements)

    def elevations(self, values: list[Any], key: str) -> tuple[float, ...]:
        out = tuple(self.number(e, key) for e in values)
        if any(abs(e) > 90 for e in out):
            raise self.fail(key, f"is {_show(values)}", "elevations in degrees within [-90, 90]")
        return out

    def sim_trajectory(self, value: Any) -> None:
        """The numbers of ``sim.trajectory`` (the sim checks its keys when it opens; a word
        where a number belongs would otherwise surface as an internal error)."""
        if value is None:
            return
        key = "sim.trajectory"
        section = self.mapping(value, key, None)
        for name in ("radius_m", "free_light_radius_m"):
            if name in section:
                self.number(section[name], f"{key}.{name}", positive=True)
        if "start_azimuth_deg" in section:
            self.number(section["start_azimuth_deg"], f"{key}.start_azimuth_deg")
        lists = {"elevations_deg": 0, "distances_m": 0, "target_m": 3, "light_offset_m": 3}
        for name, length in lists.items():
            if name not in section:
                continue
            items = section[name]
            if not isinstance(items, list) or (length and len(items) != length):
                want = f"a list of {length} numbers" if length else "a list of numbers"
                raise self.fail(f"{key}.{name}", f"is {_show(items)}", want)
            if name == "elevations_deg":
                self.elevations(items, f"{key}.{name}")
            for item in items:
                self.number(item, f"{key}.{name}", positive=name == "distances_m")

    def projector_placements(
        self, value: Any, views: int, devices: Mapping[str, Any]
    ) -> ProjectorPlacements:
        key = "plan.projector"
        if "projector" not in devices:
            raise self.fail(key, "needs a projector", "a devices.projector section")
        section = self.mapping(value, key, PROJECTOR_PLAN_KEYS)
        count = section.get("placements")
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            raise self.fail(f"{key}.placements", f"is {_show(count)}", "a positive whole number")
        per = section.get("views_per_placement", views // count)
        if isinstance(per, bool) or not isinstance(per, int) or per < 1 or per * count != views:
            raise self.fail(
                f"{key}.views_per_placement",
                f"is {_show(per)}: {count} placements x {per} views is not plan.views = {views}",
                "a whole number with placements x views_per_placement = plan.views",
            )
        return ProjectorPlacements(count, per)

    def camera_pairs(self, value: Any, n_views: int) -> tuple[CameraPair, ...]:
        key = "known_distances.camera_pairs"
        allowed = f"a list of {{views: [a, b], metres: d}} with views in 0..{n_views - 1}"
        if not isinstance(value, list):
            raise self.fail(key, f"is {_show(value)}", allowed)
        pairs = []
        for i, item in enumerate(value):
            entry = self.mapping(item, f"{key}[{i}]", ("views", "metres"))
            views = entry.get("views")
            if (
                not isinstance(views, list)
                or len(views) != 2
                or not all(isinstance(v, int) and 0 <= v < n_views for v in views)
                or views[0] == views[1]
            ):
                raise self.fail(f"{key}[{i}].views", f"is {_show(views)}", allowed)
            metres = self.number(entry.get("metres"), f"{key}[{i}].metres", positive=True)
            pairs.append(CameraPair(views[0], views[1], metres))
        return tuple(pairs)

    def light_mount(self, value: Any) -> LightMount:
        section = self.mapping(value, "light_mount", MOUNT_KEYS)
        kind = self.choice(section.get("type", "plate"), "light_mount.type", MOUNT_TYPES)
        offset = section.get("offset_m")
        if offset is None:
            return LightMount(kind, None)
        if kind == "free":
            raise self.fail(
                "light_mount.offset_m", "is set for a free light", "an offset only with type: plate"
            )
        if not isinstance(offset, list) or len(offset) != 3:
            raise self.fail(
                "light_mount.offset_m", f"is {_show(offset)}", "[x, y, z] in metres, camera frame"
            )
        x, y, z = (self.number(v, "light_mount.offset_m") for v in offset)
        return LightMount(kind, (x, y, z))

    def calibration(self, value: Any, plan: Plan) -> CalibrationChoice | None:
        if value is None:
            return None
        section = self.mapping(value, "calibration", CALIBRATION_KEYS)
        store = self.string(section.get("store", "default"), "calibration.store")
        if "camera" not in section:
            raise self.fail(
                "calibration.camera",
                "is missing",
                "the name of a camera sensitivity entry in the store",
            )
        camera = self.string(section["camera"], "calibration.camera")
        lights = self.mapping(section.get("lights", {}), "calibration.lights", None)
        for name, entry in lights.items():
            self.string(entry, f"calibration.lights.{name}")
        for name in plan.illuminations:
            lights.setdefault(name, name)
        return CalibrationChoice(store, camera, lights)


def known_drivers(kind: str) -> tuple[str, ...]:
    """Driver names accepted for ``kind``: the local ones plus the registry's, if it lists
    them (an empty tuple means "not checkable here; the registry decides at open time")."""
    try:
        registry = importlib.import_module("drivers.registry")
    except ImportError:
        return ()
    names = getattr(registry, "DRIVERS", None)
    if not isinstance(names, Mapping) or kind not in names:
        return ()
    return tuple(sorted({*LOCAL_DRIVERS[kind], *names[kind]}))


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
