"""Tethered cameras through libgphoto2 (python-gphoto2, optional extra ``gphoto2``).

Capture to the camera's RAM or card, download every file the shot produced (RAW, and JPEG
when the camera shoots both), read exposure/ISO/serial, set config values. A busy camera
("PTP device busy") is retried with bounded exponential backoff, and every library call runs
under a hard timeout so a hung camera cannot hang the session.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, TypeVar

from core.errors import MissingDependencyError, RigError
from drivers.cameras.exif import read_exif
from drivers.cameras.files import target_path, write_durably
from drivers.cameras.timeouts import call_with_timeout
from drivers.protocols import CapturedFrame

log = logging.getLogger(__name__)
T = TypeVar("T")

CAPTURE_TARGETS = {"ram": "Internal RAM", "card": "Memory card"}
SERIAL_KEYS = ("serialnumber", "eosserialnumber")


def parse_shutter(text: str) -> float | None:
    """'1/125', '0.5', '2.5s', '30"' -> seconds; 'bulb'/'auto' -> None."""
    text = text.strip().rstrip('s"').strip()
    try:
        if "/" in text:
            num, den = text.split("/", 1)
            return float(num) / float(den)
        return float(text)
    except (ValueError, ZeroDivisionError):
        return None


def parse_iso(text: str) -> float | None:
    """'400' -> 400.0; 'Auto' and other words -> None."""
    text = text.strip()
    return float(text) if text.isdigit() else None


def parse_aperture(text: str) -> float | None:
    """'f/8', 'f8', '8.0' -> 8.0."""
    text = text.strip().lower().removeprefix("f/").removeprefix("f")
    try:
        return float(text)
    except ValueError:
        return None


def closest_choice(
    choices: list[str], wanted: float, parse: Callable[[str], float | None], tolerance: float
) -> str | None:
    """The choice whose parsed value is nearest ``wanted`` in ratio, if within ``tolerance``."""
    best, best_error = None, tolerance
    for choice in choices:
        value = parse(choice)
        if value and value > 0:
            error = abs(math.log(value / wanted))
            if error <= best_error:
                best, best_error = choice, error
    return best


# Profile camera settings -> libgphoto2 config names (the first the camera has is used).
SETTING_WIDGETS = {
    "exposure_s": ("shutterspeed", "exposuretime", "shutterspeed2"),
    "iso": ("iso", "isospeed"),
    "aperture": ("aperture", "f-number", "fnumber"),
    "format": ("imageformat", "imagequality"),
}


def load_gphoto2() -> Any:
    try:
        import gphoto2
    except ImportError as error:
        raise MissingDependencyError("gphoto2", "gphoto2", "needed for tethered cameras") from error
    return gphoto2


class Gphoto2Camera:
    driver_name = "gphoto2"

    def __init__(
        self,
        gp: Any = None,
        port: str | None = None,
        capture_target: str = "ram",
        config: Mapping[str, str] | None = None,
        settings: Mapping[str, Any] | None = None,
        timeout_s: float = 30.0,
        busy_retries: int = 5,
        busy_backoff_s: float = 0.25,
        event_wait_ms: int = 1000,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.gp = gp or load_gphoto2()
        if capture_target not in CAPTURE_TARGETS:
            raise RigError(
                f"capture_target {capture_target!r} is not known",
                f"use one of {sorted(CAPTURE_TARGETS)}",
            )
        self.port = port
        self.capture_target = capture_target
        self.timeout_s = timeout_s
        self.busy_retries = busy_retries
        self.busy_backoff_s = busy_backoff_s
        self.event_wait_ms = event_wait_ms
        self._sleep = sleep
        self._hung = False
        self.camera = self.gp.Camera()
        if port:
            ports = self.gp.PortInfoList()
            ports.load()
            try:
                index = ports.lookup_path(port)
            except self.gp.GPhoto2Error:  # python-gphoto2 raises where libgphoto2 returns < 0
                index = -1
            if index < 0:
                raise RigError(f"no camera port {port!r}", "run `rig devices` to list camera ports")
            self.camera.set_port_info(ports[index])
        try:
            self._call("connect to the camera", self.camera.init)
        except RigError as error:
            raise RigError(
                f"{error.problem}",
                "switch the camera on, set it to PTP/tethering, and close other programs "
                "(e.g. gvfs: `gio mount -s gphoto2`) that hold it",
            ) from error
        self.set_config({"capturetarget": CAPTURE_TARGETS[capture_target]}, required=False)
        if settings:
            self.apply_settings(settings)
        if config:
            self.set_config(config)
        self.serial = self._first_value(SERIAL_KEYS) or "unknown"
        self.model = self._summary_line("Model:")

    # -- calls: busy retry + hard timeout ---------------------------------------------------
    def _call(self, what: str, function: Callable[..., T], *args: Any) -> T:
        if self._hung:
            raise RigError(
                "the camera stopped answering earlier", "replug it and resume the capture"
            )
        delay = self.busy_backoff_s
        for attempt in range(self.busy_retries + 1):
            try:
                return call_with_timeout(lambda: function(*args), self.timeout_s, f"camera: {what}")
            except self.gp.GPhoto2Error as error:
                busy = error.code == self.gp.GP_ERROR_CAMERA_BUSY or "busy" in str(error).lower()
                if not busy or attempt == self.busy_retries:
                    raise RigError(
                        f"camera failed to {what}: {error}",
                        "check the camera is on, unlocked and has a card/battery",
                    ) from error
                log.info("camera busy (%s); retry %d in %.2f s", what, attempt + 1, delay)
                self._sleep(delay)
                delay = min(delay * 2, 4.0)
            except RigError:
                self._hung = True
                raise
        raise AssertionError("unreachable")

    # -- config -----------------------------------------------------------------------------
    def get_config(self, name: str) -> str | None:
        config = self._call("read its settings", self.camera.get_config)
        try:
            return str(config.get_child_by_name(name).get_value())
        except self.gp.GPhoto2Error:
            return None

    def _first_value(self, names: tuple[str, ...]) -> str | None:
        for name in names:
            value = self.get_config(name)
            if value:
                return value
        return None

    def _setting_text(self, key: str) -> str:
        """The camera's value for a profile setting (``exposure_s``, ``iso``...), or ''."""
        return self._first_value(SETTING_WIDGETS[key]) or ""

    def set_config(self, values: Mapping[str, str], required: bool = True) -> None:
        config = self._call("read its settings", self.camera.get_config)
        changed = False
        for name, value in values.items():
            try:
                widget = config.get_child_by_name(name)
            except self.gp.GPhoto2Error as error:
                if required:
                    raise RigError(
                        f"the camera has no setting {name!r}",
                        "run `gphoto2 --list-config` to see the settings it offers",
                    ) from error
                continue
            try:
                _check_choice(self.gp, widget, str(value))
                widget.set_value(str(value))
            except self.gp.GPhoto2Error as error:
                choices = ", ".join(str(c) for c in widget.get_choices()) if required else ""
                if required:
                    raise RigError(
                        f"the camera refuses {name} = {value!r}", f"allowed values: {choices}"
                    ) from error
                continue
            changed = True
        if changed:
            self._call("apply settings", self.camera.set_config, config)

    def apply_settings(self, settings: Mapping[str, Any]) -> None:
        """Profile ``camera_settings`` (exposure_s, iso, aperture, format, or any raw
        libgphoto2 config name) -> the camera's own choice strings."""
        config = self._call("read its settings", self.camera.get_config)
        values: dict[str, str] = {}
        for key, wanted in settings.items():
            if key not in SETTING_WIDGETS:
                values[key] = str(wanted)
                continue
            widget_name, widget = self._find_widget(config, SETTING_WIDGETS[key])
            if widget is None:
                raise RigError(
                    f"the camera has none of the settings {', '.join(SETTING_WIDGETS[key])} "
                    f"(for camera_settings.{key})",
                    "set it on the camera by hand and remove it from the profile",
                )
            choices = [str(c) for c in widget.get_choices()]
            if key == "exposure_s":
                choice = closest_choice(choices, float(wanted), parse_shutter, 0.1)
            elif key == "aperture":
                choice = closest_choice(choices, float(wanted), parse_aperture, 0.05)
            elif key == "iso":
                choice = next((c for c in choices if c == str(int(float(wanted)))), None)
            else:
                choice = _format_choice(choices, str(wanted))
            if choice is None:
                raise RigError(
                    f"the camera offers no {widget_name} matching camera_settings.{key} = "
                    f"{wanted!r}",
                    f"choose one of: {', '.join(choices)}",
                )
            values[widget_name] = choice
        self.set_config(values)

    def _find_widget(self, config: Any, names: tuple[str, ...]) -> tuple[str, Any]:
        for name in names:
            try:
                return name, config.get_child_by_name(name)
            except self.gp.GPhoto2Error:
                continue
        return names[0], None

    def _summary_line(self, key: str) -> str | None:
        try:
            summary = str(self._call("read its summary", self.camera.get_summary))
        except RigError:
            return None
        for line in summary.splitlines():
            if line.strip().startswith(key):
                return line.split(":", 1)[1].strip()
        return None

    # -- capture ----------------------------------------------------------------------------
    def capture(self, out_dir: Path, stem: str) -> CapturedFrame:
        out_dir.mkdir(parents=True, exist_ok=True)
        first = self._call("capture", self.camera.capture, self.gp.GP_CAPTURE_IMAGE)
        sources = [(first.folder, first.name), *self._more_files()]
        taken: set[Path] = set()
        paths = []
        for folder, name in sources:
            camera_file = self._call(
                f"download {name}", self.camera.file_get, folder, name, self.gp.GP_FILE_TYPE_NORMAL
            )
            data = bytes(memoryview(camera_file.get_data_and_size()))
            path = target_path(out_dir, stem, Path(name).suffix, taken)
            write_durably(path, data)
            paths.append(path)
            if self.capture_target == "card":
                continue  # keep the card copy as a backup
            try:
                self._call(f"delete {name} from RAM", self.camera.file_delete, folder, name)
            except RigError as error:
                log.debug("could not delete %s/%s from camera RAM: %s", folder, name, error)
        exif = read_exif(paths[0])
        # the camera's current settings only where the file's EXIF lacks them
        exposure = exif.exposure_s or parse_shutter(self._setting_text("exposure_s"))
        iso = exif.iso or parse_iso(self._setting_text("iso"))
        if exposure is None or iso is None:
            raise RigError(
                f"camera did not report exposure/ISO for {paths[0].name}",
                "set the camera to manual exposure with a fixed ISO",
            )
        return CapturedFrame(
            paths=tuple(paths),
            exposure_s=exposure,
            iso=iso,
            camera_serial=exif.serial or self.serial,
            timestamp=datetime.now(timezone.utc).isoformat(timespec="milliseconds"),
            extra={"camera_files": [f"{f}/{n}" for f, n in sources]},
        )

    def _more_files(self) -> list[tuple[str, str]]:
        """Files added after the first (RAW+JPEG), until the camera reports the capture done."""
        extra = []
        for _ in range(10):
            kind, data = self._call("report events", self.camera.wait_for_event, self.event_wait_ms)
            if kind == self.gp.GP_EVENT_FILE_ADDED:
                extra.append((data.folder, data.name))
            elif kind in (self.gp.GP_EVENT_CAPTURE_COMPLETE, self.gp.GP_EVENT_TIMEOUT):
                break
        return extra

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "camera",
            "driver": self.driver_name,
            "model": self.model,
            "serial": self.serial,
            "port": self.port,
            "capture_target": self.capture_target,
        }

    def close(self) -> None:
        if not self._hung:
            try:
                self._call("disconnect", self.camera.exit)
            except RigError as error:
                log.debug("camera exit failed: %s", error)


def _format_choice(choices: list[str], wanted: str) -> str | None:
    """Exact name, else the one plain (not "RAW + JPEG") choice containing it."""
    for choice in choices:
        if choice.lower() == wanted.lower():
            return choice
    plain = [c for c in choices if wanted.lower() in c.lower() and "+" not in c]
    return plain[0] if len(plain) == 1 else None


def _check_choice(gp: Any, widget: Any, value: str) -> None:
    """A radio/menu value must be one of the widget's choices: some cameras (and libgphoto2's
    virtual one) store anything they are given and then shoot with the old setting."""
    if widget.get_type() in (gp.GP_WIDGET_RADIO, gp.GP_WIDGET_MENU):
        if value not in [str(c) for c in widget.get_choices()]:
            raise gp.GPhoto2Error(gp.GP_ERROR_BAD_PARAMETERS)
