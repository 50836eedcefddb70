"""Shared behaviour of every light: named channels, named illuminations, settle time.

Drivers subclass ``LightBase`` and implement only their wire format (``_apply``), so level
validation, illumination lookup, settling and provenance are identical for every light.
"""

from __future__ import annotations

import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

from core.errors import RigError
from drivers.transports.base import Transport

log = logging.getLogger("drivers.lights")

DEFAULT_CHANNELS = ("r", "g", "b", "c", "w")


def to_byte(level: float) -> int:
    """Level in [0, 1] to an 8-bit value, rounding to nearest."""
    return int(round(level * 255))


def colour_and_white(levels: Mapping[str, float]) -> tuple[bool, bool]:
    """Whether any of r/g/b and any of c/w is lit: Wi-Fi bulbs show colour *or* white."""
    colour = any(levels.get(c, 0.0) > 0 for c in "rgb")
    white = any(levels.get(c, 0.0) > 0 for c in "cw")
    return colour, white


def check_illuminations(
    illuminations: Mapping[str, Mapping[str, float]] | None, channels: Sequence[str], where: str
) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for name, levels in (illuminations or {}).items():
        if not isinstance(levels, Mapping):
            raise RigError(
                f"{where}.illuminations.{name} is not a mapping of channel levels",
                "write it like `LED1: {c: 1.0}`",
            )
        out[str(name)] = check_levels(levels, channels, f"{where}.illuminations.{name}")
    return out


def check_levels(
    levels: Mapping[str, float], channels: Sequence[str], where: str
) -> dict[str, float]:
    """All channels, unnamed ones 0; rejects unknown channels and levels outside [0, 1]."""
    unknown = sorted(set(levels) - set(channels))
    if unknown:
        raise RigError(
            f"{where} names unknown channel(s) {', '.join(unknown)}",
            f"this light has channels {', '.join(channels)}",
        )
    out = {channel: 0.0 for channel in channels}
    for channel, value in levels.items():
        try:
            level = float(value)
        except (TypeError, ValueError) as error:
            raise RigError(f"{where}.{channel} = {value!r} is not a number", "use 0..1") from error
        if not 0.0 <= level <= 1.0:
            raise RigError(f"{where}.{channel} = {level:g} is outside 0..1", "use a level in 0..1")
        out[channel] = level
    return out


class LightBase(ABC):
    """Implements the ``LightSource`` protocol on top of one method, ``_apply``."""

    driver_name: ClassVar[str] = "light"

    def __init__(
        self,
        channels: Sequence[str] = DEFAULT_CHANNELS,
        illuminations: Mapping[str, Mapping[str, float]] | None = None,
        settle_s: float = 0.0,
        transport: Transport | None = None,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.channels = tuple(channels)
        if not self.channels:
            raise RigError(f"{self.driver_name}: no channels named", "list the light's channels")
        self.illuminations = check_illuminations(illuminations, self.channels, self.driver_name)
        self.settle_s = float(settle_s)
        self.transport = transport
        self._sleep = sleep
        self.levels: dict[str, float] = {channel: 0.0 for channel in self.channels}
        self.current: str | None = None

    def set_levels(self, levels: Mapping[str, float]) -> None:
        full = check_levels(levels, self.channels, f"{self.driver_name} levels")
        log.info("%s: %s", self.driver_name, " ".join(f"{k}={v:.3f}" for k, v in full.items()))
        self._apply(full)
        self.levels = full
        self.current = None

    def set_illumination(self, name: str) -> None:
        if name not in self.illuminations:
            known = ", ".join(self.illuminations) or "none"
            raise RigError(
                f"illumination {name!r} is not defined for the {self.driver_name} light",
                f"define it under the light's `illuminations:` in the profile (known: {known})",
            )
        self.set_levels(self.illuminations[name])
        self.current = name
        if self.settle_s > 0:
            self._sleep(self.settle_s)

    def off(self) -> None:
        self._off()
        self.levels = {channel: 0.0 for channel in self.channels}
        self.current = None

    def describe(self) -> dict[str, Any]:
        info: dict[str, Any] = {
            "kind": "light",
            "driver": self.driver_name,
            "channels": list(self.channels),
            "illuminations": self.illuminations,
            "settle_s": self.settle_s,
        }
        if self.transport is not None:
            info["transport"] = self.transport.describe()
        info.update(self._identity())
        return info

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()

    @abstractmethod
    def _apply(self, levels: dict[str, float]) -> None:
        """Send one complete set of levels (every channel present)."""

    def _off(self) -> None:
        self._apply({channel: 0.0 for channel in self.channels})

    def _identity(self) -> dict[str, Any]:
        """Model/serial/firmware read from the device, for provenance."""
        return {}
