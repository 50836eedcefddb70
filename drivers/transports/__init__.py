"""Transports: how drivers reach a device (serial, HID, USB, TCP, subprocess), chosen by name.

``open_transport`` turns a profile's ``transport:`` section into an open transport, e.g.
``{"type": "serial", "port": "/dev/ttyUSB0", "baudrate": 57600}`` (``kind:`` is accepted
for ``type:``). Add ``record: FILE.jsonl``
to log every exchange of a real session for replay with ``{"type": "replay", "file": ...}``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from core.config import parse_value
from core.errors import RigError
from drivers.transports.base import NotAnsweringError, Transport, redact

__all__ = ["NotAnsweringError", "Transport", "open_transport", "redact", "TRANSPORT_TYPES"]

TRANSPORT_TYPES = ("serial", "hid", "usb", "tcp", "subprocess", "replay")
# The numbers a transport section may hold: a timeout of an hour or a port beyond 65535 is a
# typo, refused before anything is opened (a socket raises OverflowError on such a port).
NUMBERS: dict[str, tuple[type, dict[str, float]]] = {
    "timeout_s": (float, {"above": 0, "max": 3600}),
    "port": (int, {"min": 1, "max": 65_535}),  # tcp; a serial port is a name
    "baudrate": (int, {"min": 50, "max": 4_000_000}),
}


def _int(value: Any, key: str) -> int:
    """VID/PID may be written 0x16c0, "16c0" or 5824 in YAML; USB ids are 16 bits."""
    try:
        number = value if isinstance(value, int) and not isinstance(value, bool) else int(
            str(value), 16)
    except ValueError as error:
        raise RigError(
            f"transport.{key} = {value!r} is not a number", "write it like 0x16c0"
        ) from error
    if not 0 <= number <= 0xFFFF:
        raise RigError(f"transport.{key} = {value!r} is not a USB id",
                       "allowed: 0x0000 to 0xffff, e.g. 0x16c0")
    return number


def open_transport(spec: Mapping[str, Any], where: str = "transport") -> Transport:
    """Open the transport a profile section describes."""
    options = dict(spec)
    kind = options.pop("type", None) or options.pop("kind", None)  # profiles may say `kind:`
    options.pop("kind", None)
    record = options.pop("record", None)
    for key, (number, bounds) in NUMBERS.items():
        if key in options and not (key == "port" and kind != "tcp"):
            parse_value(options[key], number, f"{where} has a bad value", key, bounds)
    try:
        timeout = float(options.pop("timeout_s", 1.0))
        transport = _open(kind, options, timeout)
    except (TypeError, KeyError) as error:  # unknown or missing keys
        raise RigError(
            f"{where} {redact(spec)} has unexpected or missing keys ({error})",
            "see docs/usage-drivers.md for the keys each transport type takes",
        ) from error
    except ValueError as error:  # a port, timeout or baud rate that is not a valid number
        raise RigError(
            f"{where} {redact(spec)} has a bad value ({error})",
            "see docs/usage-drivers.md for the values each transport type takes",
        ) from error
    if record:
        from drivers.transports.replay import RecordingTransport

        try:
            return RecordingTransport(transport, record)
        except RigError:
            transport.close()
            raise
    return transport


def _open(kind: Any, options: dict[str, Any], timeout: float) -> Transport:
    if kind == "serial":
        from drivers.transports.serial_port import SerialTransport

        return SerialTransport(timeout_s=timeout, **options)
    if kind == "hid":
        from drivers.transports.hid_device import HidTransport

        vid, pid = _int(options.pop("vid"), "vid"), _int(options.pop("pid"), "pid")
        return HidTransport(vid, pid, timeout_s=timeout, **options)
    if kind == "usb":
        from drivers.transports.usb_device import UsbTransport

        vid, pid = _int(options.pop("vid"), "vid"), _int(options.pop("pid"), "pid")
        return UsbTransport(vid, pid, timeout_s=timeout, **options)
    if kind == "tcp":
        from drivers.transports.tcp import TcpTransport

        return TcpTransport(
            options.pop("host"), int(options.pop("port")), timeout_s=timeout, **options
        )
    if kind == "subprocess":
        from drivers.transports.subprocess_pipe import SubprocessTransport

        return SubprocessTransport(options.pop("command"), timeout_s=timeout, **options)
    if kind == "replay":
        from drivers.transports.replay import ScriptedTransport

        return ScriptedTransport.from_jsonl(options.pop("file"))
    raise RigError(f"unknown transport type {kind!r}", f"use one of: {', '.join(TRANSPORT_TYPES)}")
