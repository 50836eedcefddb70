"""DMX512 fixtures: profile channel names -> DMX addresses, levels -> a frame of slot bytes.

Every DMX interface (Enttec Pro serial, uDMX over USB, Velleman K8062 over HID) shares this
mapping and differs only in how it ships the slots, which is all each subclass implements.
"""

from __future__ import annotations

import time
from abc import abstractmethod
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from core.errors import RigError
from drivers.lights.base import LightBase, to_byte
from drivers.transports.base import Transport

DMX_SLOTS = 512


def check_address(value: Any, where: str) -> int:
    try:
        address = int(value)
    except (TypeError, ValueError) as error:
        raise RigError(f"{where} = {value!r} is not a DMX address", "use 1..512") from error
    if not 1 <= address <= DMX_SLOTS:
        raise RigError(f"{where} = {address} is outside the DMX universe", "use 1..512")
    return address


def check_slot_value(value: Any, where: str) -> int:
    """A fixed slot's 8-bit DMX value (0..255)."""
    try:
        number = int(value)
    except (TypeError, ValueError) as error:
        raise RigError(f"{where} = {value!r} is not a DMX value", "use 0..255") from error
    if not 0 <= number <= 255 or number != value:
        raise RigError(f"{where} = {value!r} is not a DMX value", "use a whole number 0..255")
    return number


def channel_addresses(
    channels: Mapping[str, int] | Sequence[str], start_address: int, where: str
) -> dict[str, int]:
    """``{r: 1, g: 2}``, or a list in the fixture's channel order from ``start_address``."""
    if isinstance(channels, Mapping):
        pairs = list(channels.items())
    else:
        pairs = [(name, start_address + i) for i, name in enumerate(channels)]
    if not pairs:
        raise RigError(f"{where}: no channel map", "give `channels: {r: 1, g: 2, b: 3, ...}`")
    return {str(name): check_address(addr, f"{where}.channels.{name}") for name, addr in pairs}


class DmxLight(LightBase):
    """A fixture (or several) in one DMX universe. ``channels`` maps names to 1-based
    addresses, or lists names in the fixture's channel order starting at ``start_address``.

    ``fixed`` holds slots that never change, e.g. a fixture's master dimmer or mode channel
    (``{6: 255}``).
    """

    def __init__(
        self,
        transport: Transport,
        channels: Mapping[str, int] | Sequence[str],
        illuminations: Mapping[str, Mapping[str, float]] | None = None,
        settle_s: float = 0.0,
        fixed: Mapping[int, int] | None = None,
        start_address: int = 1,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.addresses = channel_addresses(channels, start_address, self.driver_name)
        self.fixed = {
            check_address(addr, f"{self.driver_name}.fixed"): check_slot_value(
                value, f"{self.driver_name}.fixed.{addr}"
            )
            for addr, value in (fixed or {}).items()
        }
        clash = set(self.addresses.values()) & set(self.fixed)
        if clash:
            raise RigError(
                f"{self.driver_name}: address(es) {sorted(clash)} are both a channel and fixed",
                "give each DMX address one role",
            )
        super().__init__(tuple(self.addresses), illuminations, settle_s, transport, sleep)
        self.transport: Transport = transport
        self.used_slots = max([*self.addresses.values(), *self.fixed])

    def frame(self, levels: Mapping[str, float], size: int) -> bytes:
        """Slot values 1..size (no start code) for these levels."""
        slots = bytearray(size)
        for address, value in self.fixed.items():
            slots[address - 1] = value
        for name, level in levels.items():
            slots[self.addresses[name] - 1] = to_byte(level)
        return bytes(slots)

    def _apply(self, levels: dict[str, float]) -> None:
        self._send(self.frame(levels, self.used_slots))

    @abstractmethod
    def _send(self, slots: bytes) -> None:
        """Ship slots 1..len(slots) to the interface."""

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "dmx_addresses": self.addresses, "fixed": self.fixed}
