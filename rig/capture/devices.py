"""Open the devices a profile names through ``drivers.registry`` (``driver: manual`` lights go
to a light the person switches by hand); the devices of one opening share a ``DeviceSet``.
Device failures are turned into ``RigError`` naming the device."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from core.errors import RigError
from drivers import registry
from drivers.device_set import DeviceSet
from drivers.protocols import (
    Camera,
    GroundTruthSource,
    LightSource,
    Projector,
    SelfPositioning,
    Spectrometer,
    WhiteCardSource,
    WhiteReferenceSource,
)
from rig.profile import Profile

Ask = Callable[[str], str]
KINDS = ("camera", "light", "projector", "spectrometer")


@dataclass
class RigDevices:
    """The opened devices of one capture run."""

    camera: Camera
    light: LightSource | None = None
    projector: Projector | None = None
    spectrometer: Spectrometer | None = None
    names: dict[str, str] = field(default_factory=dict)  # kind -> driver name

    def _devices(self) -> list[Any]:
        return [
            device
            for device in (self.camera, self.light, self.projector, self.spectrometer)
            if device is not None
        ]

    @property
    def positioner(self) -> SelfPositioning | None:
        """The device that moves the rig to each view itself; None: the person moves it."""
        return next((d for d in self._devices() if isinstance(d, SelfPositioning)), None)

    @property
    def ground_truth(self) -> GroundTruthSource | None:
        """The device that knows the true scene, when one does."""
        return next((d for d in self._devices() if isinstance(d, GroundTruthSource)), None)

    @property
    def white_reference_source(self) -> WhiteReferenceSource | None:
        """The device that sets up a white reference itself; None: the person places one."""
        return next((d for d in self._devices() if isinstance(d, WhiteReferenceSource)), None)

    @property
    def white_card_source(self) -> WhiteCardSource | None:
        """The device that puts a white card in front of the camera itself; None: the person
        holds one."""
        return next((d for d in self._devices() if isinstance(d, WhiteCardSource)), None)

    def goto_view(self, view: int) -> None:
        """A self-positioning rig moves itself; a real rig is moved by the person."""
        positioner = self.positioner
        if positioner is not None:
            kind = next(k for k in KINDS if getattr(self, k) is positioner)
            with device_errors(kind, self.names.get(kind, "?"), f"move to view {view}"):
                positioner.goto_view(view)

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for kind in KINDS:
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


VALUE_ERRORS = (ValueError, TypeError, ArithmeticError, MemoryError)


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
        fix = (  # a value no device can take is not cured by re-plugging one
            f"a setting is out of what the {kind} takes: check the profile's devices.{kind}, "
            "camera_settings and sim sections (run with --debug and report it if they are right)"
            if isinstance(exc, VALUE_ERRORS)
            else "check the device's cable/power and the profile's transport"
        )
        raise RigError(
            f"{kind} ({driver}) failed to {action}: {type(exc).__name__}: {exc}", fix
        ) from exc


def device_set(profile: Profile, seed: int) -> DeviceSet:
    """What the devices opened from ``profile`` share: its plan and mounts, its seed."""
    placements = profile.plan.projector
    return DeviceSet(
        seed=seed,
        views=profile.plan.views,
        elevations_deg=tuple(profile.plan.trajectory.elevations_deg),
        distance_factors=tuple(profile.plan.trajectory.distance_factors),
        free_light=profile.light_mount.type == "free",
        light_offset_m=profile.light_mount.offset_m,
        light_diameter_m=profile.light_mount.diameter_m,
        illuminations=profile.illuminations,
        camera_settings=profile.camera_settings,
        projector_placements=None if placements is None else placements.count,
        views_per_placement=None if placements is None else placements.views_per_placement,
        board=profile.board,
        simulation=profile.sim,
    )


def open_devices(
    profile: Profile,
    seed: int,
    ask: Ask | None,
    kinds: tuple[str, ...] = ("camera", "light", "projector"),
) -> RigDevices:
    """Open every device of ``kinds`` the profile names (the spectrometer only for the
    calibration wizard)."""
    shared = device_set(profile, seed)
    opened: dict[str, Any] = {}
    names: dict[str, str] = {}
    try:
        for kind in kinds:
            spec = profile.device(kind)
            if spec is None:
                continue
            driver = str(spec["driver"])
            names[kind] = driver
            if driver == "manual" and kind == "light":
                device = open_manual_light(spec, profile, ask)
            else:
                device = _open_registry(kind, spec, profile, shared)
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


def _open_registry(
    kind: str, spec: Mapping[str, Any], profile: Profile, shared: DeviceSet
) -> Any:
    spec = dict(spec)
    if kind == "camera" and profile.camera_settings:
        spec["settings"] = {**dict(profile.camera_settings), **spec.get("settings", {})}
    if kind == "light":
        spec.setdefault("illuminations", {k: dict(v) for k, v in profile.illuminations.items()})
    opener = getattr(registry, f"open_{kind}")
    with device_errors(kind, str(spec["driver"]), "open"):
        return opener(spec, shared)
