"""Serial ports through pyserial (USB-serial DMX widgets, microcontroller light controllers)."""

from __future__ import annotations

import errno
import importlib
from typing import Any

from core.errors import RigError
from drivers.transports.base import Transport

UDEV_HINT = (
    "add yourself to the `dialout` group (`sudo usermod -aG dialout $USER`, then log in again) "
    'or install a udev rule giving the device MODE="0666", e.g. '
    'SUBSYSTEM=="tty", ATTRS{idVendor}=="0403", MODE="0666" in '
    "/etc/udev/rules.d/99-spectral-rig.rules"
)


class SerialTransport(Transport):
    kind = "serial"

    def __init__(
        self,
        port: str,
        baudrate: int = 115200,
        timeout_s: float = 1.0,
        serial_module: Any = None,
        **options: Any,
    ) -> None:
        super().__init__(port, timeout_s)
        if serial_module is None:
            serial_module = importlib.import_module("serial")
        self._serial = serial_module  # its exception classes, for the fake one in tests too
        self.baudrate = baudrate
        try:
            self._port = serial_module.Serial(
                port=port,
                baudrate=baudrate,
                timeout=timeout_s,
                write_timeout=timeout_s,
                **options,
            )
        except serial_module.SerialException as error:
            raise open_error(port, error) from error

    def _write(self, data: bytes) -> None:
        try:
            self._port.write(data)
            self._port.flush()
        except self._serial.SerialTimeoutException as error:
            raise self.not_answering("the write to finish") from error
        except self._serial.SerialException as error:
            raise RigError(
                f"serial port {self.address} failed: {error}", "reconnect the device"
            ) from error

    def _read(self, size: int) -> bytes:
        try:
            return bytes(self._port.read(size))
        except self._serial.SerialException as error:
            raise RigError(
                f"serial port {self.address} failed: {error}", "reconnect the device"
            ) from error

    def _flush_input(self) -> None:
        self._port.reset_input_buffer()

    def _close(self) -> None:
        self._port.close()

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "baudrate": self.baudrate}


def open_error(port: str, error: Exception) -> RigError:
    """Turn pyserial's open failure into the fix the person needs."""
    code = getattr(error, "errno", None)
    if code == errno.ENOENT or "No such file" in str(error) or "FileNotFoundError" in str(error):
        return RigError(
            f"serial port {port} does not exist",
            "plug the device in and run `rig devices` to see the ports present",
        )
    if code == errno.EACCES or "Permission denied" in str(error):
        return RigError(f"permission denied opening serial port {port}", UDEV_HINT)
    if code == errno.EBUSY or "busy" in str(error).lower():
        return RigError(f"serial port {port} is busy", "close the other program using it")
    return RigError(
        f"cannot open serial port {port}: {error}", "check the port named in the profile"
    )
