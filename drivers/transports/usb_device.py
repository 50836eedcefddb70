"""Raw USB through pyusb, expressed as bytes so tests can script it.

A control transfer is written in its wire form: the 8-byte SETUP packet (bmRequestType,
bRequest, wValue, wIndex, wLength, little-endian) followed, for OUT transfers, by the data
stage. For IN transfers the data stage is then ``read``. ``control_out``/``control_in`` build
these bytes for drivers, so the uDMX driver and its byte script speak the same language.
"""

from __future__ import annotations

import errno
import importlib
import struct
from typing import Any

from core.errors import MissingDependencyError, RigError
from drivers.transports.base import Transport

USB_UDEV_HINT = (
    "install a udev rule such as "
    'SUBSYSTEM=="usb", ATTRS{{idVendor}}=="{vid:04x}", ATTRS{{idProduct}}=="{pid:04x}", '
    'MODE="0666" in /etc/udev/rules.d/99-spectral-rig.rules, then `sudo udevadm control '
    "--reload && sudo udevadm trigger` and replug the device"
)

# bmRequestType values (USB 2.0 §9.3): direction | type | recipient.
VENDOR_OUT = 0x40
VENDOR_IN = 0xC0


def setup_packet(request_type: int, request: int, value: int, index: int, length: int) -> bytes:
    return struct.pack("<BBHHH", request_type, request, value, index, length)


def control_out(
    transport: Transport, request_type: int, request: int, value: int, index: int, data: bytes = b""
) -> None:
    if request_type & 0x80:
        raise ValueError("control_out needs an OUT request type (bit 7 clear)")
    transport.write(setup_packet(request_type, request, value, index, len(data)) + data)


def control_in(
    transport: Transport, request_type: int, request: int, value: int, index: int, length: int
) -> bytes:
    if not request_type & 0x80:
        raise ValueError("control_in needs an IN request type (bit 7 set)")
    transport.write(setup_packet(request_type, request, value, index, length))
    return transport.read_exactly(length, what=f"control transfer {request:#04x}")


class UsbTransport(Transport):
    kind = "usb"

    def __init__(
        self,
        vid: int,
        pid: int,
        serial: str | None = None,
        product: str | None = None,
        timeout_s: float = 1.0,
        usb_core: Any = None,
    ) -> None:
        super().__init__(f"{vid:04x}:{pid:04x}" + (f" #{serial}" if serial else ""), timeout_s)
        if usb_core is None:
            usb_core = importlib.import_module("usb.core")
        self._core = usb_core
        self.vid, self.pid = vid, pid
        try:
            found = list(usb_core.find(find_all=True, idVendor=vid, idProduct=pid))
        except usb_core.NoBackendError as error:
            raise MissingDependencyError(
                "libusb-1.0",
                None,
                "pyusb needs the libusb system library (Debian: `sudo apt install libusb-1.0-0`)",
            ) from error
        if serial is not None:
            found = [d for d in found if string_descriptor(d, "serial_number") == serial]
        if not found:
            raise RigError(
                f"no USB device {self.address} is connected", "plug it in and run `rig devices`"
            )
        if product is not None:
            found = self._with_product(found, product)
        self._dev = found[0]
        self._pending = b""

    def _with_product(self, devices: list[Any], product: str) -> list[Any]:
        """Devices whose product string is ``product``: shared VID/PIDs (the V-USB 16c0:05dc
        of uDMX is also a USBasp programmer's) must not get another device's requests."""
        names = [string_descriptor(d, "product") for d in devices]
        matching = [d for d, name in zip(devices, names, strict=True) if name == product]
        if matching:
            return matching
        if None in names:
            raise RigError(
                f"cannot read the product name of USB device {self.address} (permission denied?)",
                USB_UDEV_HINT.format(vid=self.vid, pid=self.pid),
            )
        raise RigError(
            f"USB device {self.address} is {', '.join(repr(n) for n in names)}, not {product!r}",
            f"that id is shared with other devices: plug in the {product} or fix the profile",
        )

    def _write(self, data: bytes) -> None:
        if len(data) < 8:
            raise ValueError("a USB control transfer starts with an 8-byte SETUP packet")
        request_type, request, value, index, length = struct.unpack("<BBHHH", data[:8])
        payload: Any = length if request_type & 0x80 else data[8:]
        try:
            result = self._dev.ctrl_transfer(
                request_type, request, value, index, payload, int(self.timeout_s * 1000)
            )
        except self._core.USBTimeoutError as error:
            raise self.not_answering(f"control transfer {request:#04x}") from error
        except self._core.USBError as error:
            if getattr(error, "errno", None) == errno.EACCES:
                raise RigError(
                    f"permission denied on USB device {self.address}",
                    USB_UDEV_HINT.format(vid=self.vid, pid=self.pid),
                ) from error
            raise RigError(f"USB device {self.address} failed: {error}", "replug it") from error
        if request_type & 0x80:
            self._pending += bytes(result)

    def _read(self, size: int) -> bytes:
        out, self._pending = self._pending[:size], self._pending[size:]
        return out

    def _close(self) -> None:
        import usb.util

        usb.util.dispose_resources(self._dev)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "vid": f"{self.vid:04x}", "pid": f"{self.pid:04x}"}


def string_descriptor(device: Any, name: str) -> str | None:
    """A string descriptor (pyusb's ``serial_number``, ``product``), None when unreadable."""
    try:
        value = getattr(device, name)
    except Exception:  # pyusb raises ValueError/USBError without permission or descriptor
        return None
    return None if value is None else str(value)
