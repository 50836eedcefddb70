"""Tuya Wi-Fi bulbs through tinytuya (optional extra ``tuya``).

Tuya's LAN protocol is encrypted with each device's local key, so this driver talks to a
``tinytuya.BulbDevice`` rather than bytes, and tests use a fake one. Tuya bulbs are either in
colour mode or white mode: an illumination uses r/g/b (colour, HSV from the RGB levels) or
c/w (white: brightness = c + w, colour temperature = c / (c + w), cool = 100 %), never both.
The local key is never logged or written to a session.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

from core.errors import MissingDependencyError, RigError
from drivers.lights.base import LightBase, colour_and_white, to_byte

CHANNELS = ("r", "g", "b", "c", "w")


def white_setting(levels: Mapping[str, float]) -> tuple[int, int]:
    """(brightness %, colour temperature % with 100 = coolest) for the c/w levels."""
    c, w = levels.get("c", 0.0), levels.get("w", 0.0)
    total = c + w
    if total > 1.0 + 1e-9:
        raise RigError(
            f"white levels c={c:g} + w={w:g} exceed 1",
            "a Tuya bulb's white mode has one brightness: keep c + w <= 1",
        )
    return int(round(total * 100)), int(round(100 * c / total)) if total else 0


def open_bulb(device_id: str, address: str, local_key: str, version: float = 3.3) -> Any:
    try:
        import tinytuya
    except ImportError as error:
        raise MissingDependencyError("tinytuya", "tuya", "needed for Tuya bulbs") from error
    bulb = tinytuya.BulbDevice(device_id, address, local_key)
    bulb.set_version(float(version))
    bulb.set_socketTimeout(5)
    return bulb


class TuyaBulb(LightBase):
    driver_name = "tuya"

    def __init__(
        self,
        bulb: Any,
        illuminations: Mapping[str, Mapping[str, float]] | None = None,
        settle_s: float = 1.0,
        address: str = "",
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        super().__init__(CHANNELS, illuminations, settle_s, None, sleep)
        self.bulb = bulb
        self.address = address
        for name, levels in self.illuminations.items():
            self._check_exclusive(levels, f"illumination {name!r}")

    @staticmethod
    def _check_exclusive(levels: Mapping[str, float], what: str) -> bool:
        """True for colour mode; raises for a colour + white mix."""
        colour, white = colour_and_white(levels)
        if colour and white:
            raise RigError(
                f"{what} mixes colour (r/g/b) and white (c/w) channels",
                "Tuya bulbs show colour or white, not both: split it into two illuminations",
            )
        if not colour:
            white_setting(levels)
        return colour

    def _call(self, method: str, *args: Any) -> None:
        result = getattr(self.bulb, method)(*args)
        if isinstance(result, dict) and ("Error" in result or "Err" in result):
            raise RigError(
                f"Tuya bulb {self.address or '?'} refused {method}: {result.get('Error', result)}",
                "check the device id, IP address, local key and protocol version in the profile",
            )

    def _apply(self, levels: dict[str, float]) -> None:
        if not any(levels.values()):
            self._off()
            return
        self._call("turn_on")
        if self._check_exclusive(levels, "levels"):
            self._call("set_colour", *(to_byte(levels[c]) for c in "rgb"))
        else:
            brightness, temperature = white_setting(levels)
            self._call("set_white_percentage", brightness, temperature)

    def _off(self) -> None:
        self._call("turn_off")

    def _identity(self) -> dict[str, Any]:
        return {"address": self.address, "device_id": getattr(self.bulb, "id", None)}
