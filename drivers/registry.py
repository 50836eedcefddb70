"""Backends by name (as python-seabreeze picks backends): a profile section names its
``driver`` and this module builds it with its transport. Devices opened together from one
profile share a :class:`~drivers.device_set.DeviceSet` (``driver: sim`` devices share one
simulated world through it).
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable, Mapping
from typing import Any

from core.config import check_arguments, from_mapping
from core.errors import RigError
from drivers.device_set import DeviceSet
from drivers.lights.k8062 import K8062_PID, VELLEMAN_VID
from drivers.lights.magichome import PORT as MAGIC_HOME_PORT
from drivers.lights.udmx import UDMX_PID, UDMX_PRODUCT, UDMX_VID
from drivers.protocols import Camera, LightSource, Projector, Spectrometer
from drivers.transports import open_transport, redact
from drivers.transports.base import Transport

log = logging.getLogger(__name__)

# (vid, pid) -> (driver, what it is), for `rig devices`.
USB_IDS: dict[tuple[int, int], tuple[str, str]] = {
    (0x0403, 0x6001): ("enttec-dmx-pro", "FTDI serial (Enttec DMX USB Pro and compatibles)"),
    (UDMX_VID, UDMX_PID): ("udmx", "uDMX (anyma.ch) USB DMX"),
    (VELLEMAN_VID, K8062_PID): ("velleman-k8062", "Velleman K8062 / VM116 DMX"),
    (0x2341, 0x0043): ("rgbcw-serial", "Arduino Uno (rgbcw-text firmware?)"),
    (0x2341, 0x0058): ("rgbcw-serial", "Arduino Nano Every (rgbcw-text firmware?)"),
    (0x1A86, 0x7523): ("rgbcw-serial", "CH340 USB serial (Arduino clone, rgbcw-text firmware?)"),
    (0x10C4, 0xEA60): ("rgbcw-serial", "CP210x USB serial (ESP32, rgbcw-text firmware?)"),
    (0x2E8A, 0x000A): ("rgbcw-serial", "Raspberry Pi Pico (rgbcw-text firmware?)"),
}
OCEAN_VID = 0x2457

DEFAULT_TRANSPORTS: dict[str, dict[str, Any]] = {
    "enttec-dmx-pro": {"type": "serial", "baudrate": 57600},
    "dmx": {"type": "serial", "baudrate": 57600},
    "rgbcw-serial": {"type": "serial", "baudrate": 115200},
    "udmx": {"type": "usb", "vid": UDMX_VID, "pid": UDMX_PID, "product": UDMX_PRODUCT},
    "velleman-k8062": {"type": "hid", "vid": VELLEMAN_VID, "pid": K8062_PID},
    "magic-home": {"type": "tcp", "port": MAGIC_HOME_PORT},
}


def _section(spec: Mapping[str, Any], kind: str) -> tuple[str, dict[str, Any]]:
    if not isinstance(spec, Mapping):
        raise RigError(
            f"the {kind} section of the profile is not a mapping", "see docs/usage-drivers.md"
        )
    options = dict(spec)
    driver = options.pop("driver", None)
    if not driver:
        raise RigError(
            f"the {kind} section has no `driver:`",
            f"name one of: {', '.join(list_driver_names(kind))}",
        )
    return str(driver), options


def _transport_section(options: dict[str, Any]) -> dict[str, Any]:
    """The section's ``transport:`` (``kind:`` read as ``type:``)."""
    spec = dict(options.pop("transport", None) or {})
    if "kind" in spec:
        spec["type"] = spec.pop("kind")
    return spec


def resolved_transport(driver: str, section: Mapping[str, Any] | None) -> dict[str, Any]:
    """The transport a device section opens: the profile's ``transport:`` over the driver's
    default; the defaults (a baud rate, a VID) apply only to the default's own type, so e.g. a
    ``subprocess`` bridge can replace the serial port of any light. Also what the resume
    trust check reads, so the two cannot disagree on what would run."""
    given = _transport_section({"transport": dict(section or {})})
    default = DEFAULT_TRANSPORTS.get(driver, {})
    if given.get("type", default.get("type")) != default.get("type"):
        default = {}
    return {**default, **given}


def _transport(driver: str, options: dict[str, Any]) -> Transport:
    """Open the section's transport (:func:`resolved_transport`), taking it out of
    ``options``."""
    spec = resolved_transport(driver, options.pop("transport", None))
    if "type" not in spec:
        raise RigError(f"driver {driver} needs a `transport:` section", "see docs/usage-drivers.md")
    return open_transport(spec, where=f"{driver}.transport")


def _build(
    kind: str, driver: str, cls: Callable[..., Any], options: dict[str, Any], *args: Any
) -> Any:
    """``cls(*args, **options)``, the profile's ``options`` checked against ``cls``'s
    annotations first (unknown, missing or mistyped keys are a RigError naming the key)."""
    log.debug("opening %s driver %s with %s", kind, driver, redact(options))
    check_arguments(cls, options, f"{kind} driver {driver!r}", skip=len(args),
                    bounds=OPTION_BOUNDS)
    return cls(*args, **options)


Factory = Callable[[str, dict[str, Any], DeviceSet], Any]

# Bounds of the numbers drivers take from a profile, by option name (the same meaning in every
# driver): a value beyond them is a typo, refused before the device is asked to do it.
OPTION_BOUNDS: dict[str, dict[str, float]] = {
    "settle_s": {"min": 0, "max": 600},
    "timeout_s": {"above": 0, "max": 86_400},
    "stable_s": {"min": 0, "max": 3600},
    "poll_s": {"above": 0, "max": 60},
    "exposure_s": {"above": 0, "max": 3600},
    "iso": {"above": 0, "max": 1e6},
    "frame_count": {"min": 1, "max": 100_000},
    "boot_tries": {"min": 1, "max": 100},
    "busy_retries": {"min": 0, "max": 100},
    "busy_backoff_s": {"min": 0, "max": 60},
    "event_wait_ms": {"min": 1, "max": 600_000},
    "start_address": {"min": 1, "max": 512},  # DMX slots
    "display": {"min": 0, "max": 64},
    "integration_time_s": {"above": 0, "max": 600},
    "max_integration_s": {"above": 0, "max": 600},
    "averages": {"min": 1, "max": 10_000},
    "target_fraction": {"above": 0, "max": 1},
    "saturation_fraction": {"above": 0, "max": 1},
}


def _with_transport(cls_path: str) -> Factory:
    def make(driver: str, options: dict[str, Any], devices: DeviceSet) -> Any:
        module, _, name = cls_path.rpartition(".")
        cls = getattr(importlib.import_module(module), name)
        transport = _transport(driver, options)
        try:
            return _build("light", driver, cls, options, transport)
        except BaseException:
            transport.close()
            raise

    return make


def _sim(kind: str) -> Factory:
    """The ``kind`` of the set's simulated rig (one world per device set)."""

    def make(driver: str, options: dict[str, Any], devices: DeviceSet) -> Any:
        try:
            from drivers.sim.world import shared_rig
        except ImportError as exc:
            raise RigError(
                "the simulated rig (drivers.sim) is not available",
                f"install spectral-rig completely ({exc})",
            ) from exc
        return getattr(shared_rig(devices), kind)

    return make


PLACEHOLDER = "REPLACE-WITH-"  # how shipped profiles mark a value only the user can know


def _tuya(driver: str, options: dict[str, Any], devices: DeviceSet) -> Any:
    from drivers.lights.tuya import TuyaBulb, open_bulb

    for key in ("device_id", "local_key"):
        if str(options.get(key, "")).startswith(PLACEHOLDER):
            raise RigError(
                f"tuya light: {key} is still the shipped placeholder {options[key]!r}",
                "get the bulb's device id and local key with `python -m tinytuya wizard` "
                "(docs/first-scan.md#tuya-and-smart-life-bulbs) and put them in the profile",
            )
    host = _transport_section(options).get("host")
    if host and "address" not in options:
        options["address"] = host
    try:
        bulb = open_bulb(
            options.pop("device_id"),
            options.pop("address"),
            options.pop("local_key"),
            options.pop("version", 3.3),
        )
    except KeyError as error:
        raise RigError(
            f"tuya light needs {error.args[0]}", "get it with `python -m tinytuya wizard`"
        ) from error
    options.setdefault("address", str(bulb.address))
    return _build("light", driver, TuyaBulb, options, bulb)


def _manual(driver: str, options: dict[str, Any], devices: DeviceSet) -> Any:
    from drivers.lights.manual import ManualLight

    return _build("light", driver, ManualLight, options)


LIGHTS: dict[str, Factory] = {
    "enttec-dmx-pro": _with_transport("drivers.lights.enttec.EnttecDmxPro"),
    "dmx": _with_transport("drivers.lights.enttec.EnttecDmxPro"),  # the common interface
    "rgbcw-serial": _with_transport("drivers.lights.rgbcw_serial.RgbcwSerialLight"),
    "udmx": _with_transport("drivers.lights.udmx.UDmx"),
    "velleman-k8062": _with_transport("drivers.lights.k8062.VellemanK8062"),
    "magic-home": _with_transport("drivers.lights.magichome.MagicHomeLight"),
    "tuya": _tuya,
    "manual": _manual,
    "sim": _sim("light"),
}


def _gphoto2(driver: str, options: dict[str, Any], devices: DeviceSet) -> Any:
    """``transport: {kind: usb, port: "usb:001,005"}`` or ``port:`` picks one camera;
    ``settings`` (the profile's camera_settings) are applied to the camera."""
    from drivers.cameras.gphoto2_camera import Gphoto2Camera

    port = _transport_section(options).get("port")
    if port and "port" not in options:
        options["port"] = port
    return _build("camera", driver, Gphoto2Camera, options)


def _file_camera(cls_path: str) -> Factory:
    """Cameras that only find files: the profile's exposure/ISO are their metadata fallback."""

    def make(driver: str, options: dict[str, Any], devices: DeviceSet) -> Any:
        module, _, name = cls_path.rpartition(".")
        cls = getattr(importlib.import_module(module), name)
        settings = options.pop("settings", None) or {}
        for key in ("exposure_s", "iso"):
            if key in settings:
                options.setdefault(key, settings[key])
        _transport_section(options)
        return _build("camera", driver, cls, options)

    return make


CAMERAS: dict[str, Factory] = {
    "gphoto2": _gphoto2,
    "folder-watch": _file_camera("drivers.cameras.folder_watch.FolderWatchCamera"),
    "handheld-import": _file_camera("drivers.cameras.handheld.HandheldImportCamera"),
    "sim": _sim("camera"),
}


def _pygame(driver: str, options: dict[str, Any], devices: DeviceSet) -> Any:
    from drivers.projectors.pygame_display import PygameProjector

    if "size" in options:
        options["size"] = tuple(options["size"])
    return _build("projector", driver, PygameProjector, options)


PROJECTORS: dict[str, Factory] = {"pygame": _pygame, "sim": _sim("projector")}


def _seabreeze(driver: str, options: dict[str, Any], devices: DeviceSet) -> Any:
    from drivers.spectrometers.seabreeze_spectrometer import SeabreezeSpectrometer, open_seabreeze

    device = open_seabreeze(options.pop("serial", None), options.pop("backend", None))
    try:
        return _build("spectrometer", driver, SeabreezeSpectrometer, options, device)
    except BaseException:
        device.close()
        raise


def _file_import(driver: str, options: dict[str, Any], devices: DeviceSet) -> Any:
    from drivers.spectrometers.file_import import FileImportSpectrometer

    return _build("spectrometer", driver, FileImportSpectrometer, options)


SPECTROMETERS: dict[str, Factory] = {
    "seabreeze": _seabreeze,
    "file-import": _file_import,
    "sim": _sim("spectrometer"),
}

# Drivers whose devices know the scene they show (GroundTruthSource), e.g. its true poses.
GROUND_TRUTH_DRIVERS = frozenset({"sim"})


def check_simulation(section: Mapping[str, Any], source: str) -> None:
    """Check a profile's ``sim`` section (its numbers' bounds, its trajectory) when the profile
    loads (the simulated rig reads the section only when it opens); errors name ``source`` and
    the key."""
    if not section:
        return
    from drivers.sim.rig import SimConfig
    from drivers.sim.trajectory import TrajectoryConfig

    from_mapping(SimConfig, section, source, "sim")
    if "trajectory" in section:
        from_mapping(TrajectoryConfig, section["trajectory"], source, "sim.trajectory")

KINDS = {"light": LIGHTS, "camera": CAMERAS, "projector": PROJECTORS, "spectrometer": SPECTROMETERS}
# Names per kind, read by profile validation (rig.profile.known_drivers).
DRIVERS: dict[str, tuple[str, ...]] = {kind: tuple(sorted(t)) for kind, t in KINDS.items()}


def list_driver_names(kind: str | None = None) -> list[str]:
    """Driver names for one kind (light, camera, projector, spectrometer), or all of them."""
    if kind is None:
        return sorted({name for table in KINDS.values() for name in table})
    return sorted(KINDS[kind])


def _open(kind: str, spec: Mapping[str, Any], devices: DeviceSet | None) -> Any:
    driver, options = _section(spec, kind)
    table = KINDS[kind]
    if driver not in table:
        raise RigError(
            f"unknown {kind} driver {driver!r}", f"use one of: {', '.join(sorted(table))}"
        )
    return table[driver](driver, options, DeviceSet() if devices is None else devices)


def open_light(spec: Mapping[str, Any], devices: DeviceSet | None = None) -> LightSource:
    return _open("light", spec, devices)


def open_camera(spec: Mapping[str, Any], devices: DeviceSet | None = None) -> Camera:
    return _open("camera", spec, devices)


def open_projector(spec: Mapping[str, Any], devices: DeviceSet | None = None) -> Projector:
    return _open("projector", spec, devices)


def open_spectrometer(spec: Mapping[str, Any], devices: DeviceSet | None = None) -> Spectrometer:
    return _open("spectrometer", spec, devices)
