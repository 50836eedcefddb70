"""Enttec DMX USB Pro (and compatible widgets) over a serial port.

Messages are ``0x7E, label, length LSB, length MSB, data..., 0xE7`` (Enttec "DMX USB Pro
Widget API"). Label 6 sends a universe (start code 0 + 24..512 slots); label 10 reads the
widget serial number and label 3 its firmware and timing parameters. See
docs/protocols/enttec-dmx-usb-pro.md.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from core.errors import RigError
from drivers.lights.dmx import DMX_SLOTS, DmxLight
from drivers.transports.base import NotAnsweringError, Transport

START, END = 0x7E, 0xE7
LABEL_GET_PARAMETERS = 3
LABEL_SEND_DMX = 6
LABEL_GET_SERIAL = 10
MIN_SLOTS = 24


def message(label: int, data: bytes = b"") -> bytes:
    return bytes([START, label]) + struct.pack("<H", len(data)) + data + bytes([END])


def read_message(transport: Transport, label: int) -> bytes:
    """Read one reply message with ``label``; skip stray bytes before its start byte."""
    for _ in range(600):  # bounded resync: at most one stray universe before the reply
        if transport.read_exactly(1, f"Enttec reply label {label}")[0] == START:
            break
    else:
        raise RigError(
            f"{transport.address}: no Enttec message start byte", "is this an Enttec Pro?"
        )
    got_label, length = struct.unpack(
        "<BH", transport.read_exactly(3, f"Enttec label {label} header")
    )
    data = transport.read_exactly(length + 1, f"Enttec label {label} body")
    if data[-1] != END or got_label != label:
        raise RigError(
            f"{transport.address} answered label {got_label} (wanted {label}) or malformed",
            "check that the device is an Enttec DMX USB Pro compatible widget",
        )
    return data[:-1]


def bcd_serial(data: bytes) -> str:
    """Label 10 reply: 4 bytes, little-endian BCD (Enttec API)."""
    return "".join(f"{b:02x}" for b in reversed(data[:4]))


class EnttecDmxPro(DmxLight):
    driver_name = "enttec-dmx-pro"

    def __init__(
        self,
        transport: Transport,
        channels: Mapping[str, int] | Sequence[str],
        illuminations: Mapping[str, Mapping[str, float]] | None = None,
        settle_s: float = 0.0,
        fixed: Mapping[int, int] | None = None,
        start_address: int = 1,
        universe_size: int = DMX_SLOTS,
        identify: bool = True,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        super().__init__(transport, channels, illuminations, settle_s, fixed, start_address, sleep)
        if not max(MIN_SLOTS, self.used_slots) <= universe_size <= DMX_SLOTS:
            raise RigError(
                f"{self.driver_name}.universe_size = {universe_size}",
                f"use {max(MIN_SLOTS, self.used_slots)}..{DMX_SLOTS}",
            )
        self.universe_size = universe_size
        self.identity: dict[str, Any] = {}
        if identify:
            self.identity = self.read_identity()

    def read_identity(self) -> dict[str, Any]:
        """Serial number (label 10) and firmware/timing (label 3)."""
        try:
            self.transport.flush_input()
            self.transport.write(message(LABEL_GET_SERIAL))
            serial = bcd_serial(read_message(self.transport, LABEL_GET_SERIAL))
            self.transport.write(message(LABEL_GET_PARAMETERS, b"\x00\x00"))
            params = read_message(self.transport, LABEL_GET_PARAMETERS)
        except NotAnsweringError as error:
            raise RigError(
                f"{error.problem} (no reply to the Enttec serial-number request)",
                "check the port; some clone widgets cannot answer: set `identify: false`",
            ) from error
        if len(params) < 5:
            raise RigError(f"{self.transport.address}: short Enttec parameters reply", "replug it")
        return {
            "serial": serial,
            "firmware": f"{params[1]}.{params[0]}",
            "break_us": round(params[2] * 10.67, 1),
            "mark_after_break_us": round(params[3] * 10.67, 1),
            "refresh_hz": params[4],
        }

    def _send(self, slots: bytes) -> None:
        universe = slots + bytes(self.universe_size - len(slots))
        self.transport.write(message(LABEL_SEND_DMX, b"\x00" + universe))

    def _identity(self) -> dict[str, Any]:
        return dict(self.identity)
