"""Transports: how drivers reach a device (serial, HID, USB, TCP, subprocess), chosen by name.

``open_transport`` turns a profile's ``transport:`` section into an open transport, e.g.
``{"type": "serial", "port": "/dev/ttyUSB0", "baudrate": 57600}`` (``kind:`` is accepted
for ``type:``). Add ``record: FILE.jsonl``
to log every exchange of a real session for replay with ``{"type": "replay", "file": ...}``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from core.errors import RigError
from drivers.transports.base import NotAnsweringError, Transport, redact

__all__ = ["NotAnsweringError", "Transport", "open_transport", "redact", "TRANSPORT_TYPES"]

TRANSPORT_TYPES = ("serial", "hid", "usb", "tcp", "subprocess", "replay")


def _int(value: Any, key: str) -> int:
    """VID/PID may be written 0x16c0, "16c0" or 5824 in YAML."""
    if isinstance(value, int):
        return value
    try:
        return int(str(value), 16)
    except ValueError as error:
        raise RigError(
            f"transport.{key} = {value!r} is not a number", "write it like 0x16c0"
        ) from error


def open_transport(spec: Mapping[str, Any], where: str = "transport") -> Transport:
    """Open the transport a profile section describes."""
    options = dict(spec)
    kind = options.pop("type", None) or options.pop("kind", None)  # profiles may say `kind:`
    options.pop("kind", None)
    record = options.pop("record", None)
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
