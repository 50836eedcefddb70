"""HID devices through hidapi (e.g. the Velleman K8062 / VM116 DMX interface).

One ``write`` is one output report, one ``read`` one input report. hidapi wants the report
number as the first byte; devices without numbered reports use 0, which this transport adds
so drivers and byte scripts see only the report payload.
"""

from __future__ import annotations

import importlib
from typing import Any

from core.errors import RigError
from drivers.transports.base import Transport

HID_UDEV_HINT = (
    "install a udev rule such as "
    'SUBSYSTEM=="hidraw", ATTRS{{idVendor}}=="{vid:04x}", ATTRS{{idProduct}}=="{pid:04x}", '
    'MODE="0666" in /etc/udev/rules.d/99-spectral-rig.rules, then `sudo udevadm control '
    "--reload && sudo udevadm trigger` and replug the device"
)


class HidTransport(Transport):
    kind = "hid"

    def __init__(
        self,
        vid: int,
        pid: int,
        serial: str | None = None,
        path: str | None = None,
        report_id: int = 0,
        timeout_s: float = 1.0,
        hid_module: Any = None,
    ) -> None:
        super().__init__(
            path or f"{vid:04x}:{pid:04x}" + (f" #{serial}" if serial else ""), timeout_s
        )
        if hid_module is None:
            try:
                hid_module = importlib.import_module("hid")
            except ImportError as error:  # the hidapi wheel needs libhidapi on some systems
                raise RigError(
                    f"hidapi cannot be loaded ({error})",
                    "install the system library (Debian: `sudo apt install libhidapi-hidraw0`) "
                    "and `pip install hidapi`",
                ) from error
        self.report_id = report_id
        matches = hid_module.enumerate(vid, pid)
        if not matches and path is None:
            raise RigError(
                f"no HID device {vid:04x}:{pid:04x} is connected",
                "plug it in and run `rig devices`",
            )
        self._dev = hid_module.device()
        try:
            if path is not None:
                self._dev.open_path(path.encode())
            else:
                self._dev.open(vid, pid, serial)
        except OSError as error:
            raise RigError(
                f"cannot open HID device {self.address}: {error} (usually a permission problem)",
                HID_UDEV_HINT.format(vid=vid, pid=pid),
            ) from error
        self.vid, self.pid = vid, pid

    def _write(self, data: bytes) -> None:
        try:
            written = self._dev.write(bytes([self.report_id]) + data)
        except OSError as error:  # newer hidapi raises where older returns -1
            raise self._failed("writing to", error) from error
        if written < 0:
            raise self._failed("writing to")

    def _read(self, size: int) -> bytes:
        try:
            return bytes(self._dev.read(size, int(self.timeout_s * 1000)))
        except OSError as error:  # e.g. unplugged
            raise self._failed("reading from", error) from error

    def _failed(self, action: str, error: OSError | None = None) -> RigError:
        reason = f": {error}" if error else ""
        return RigError(f"{action} HID device {self.address} failed{reason}", "replug the device")

    def _close(self) -> None:
        self._dev.close()

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "vid": f"{self.vid:04x}", "pid": f"{self.pid:04x}"}
