"""Magic Home / flux LED Wi-Fi bulbs and controllers (LEDENET protocol, TCP port 5577).

Messages end in a checksum byte, the low byte of the sum of the others. Levels use the
9-byte message ``[0x31|0x41, R, G, B, WW, CW, mode, 0x0F, sum]`` (0x31 persists the colour,
0x41 does not; mode 0xF0 colours, 0x0F whites, 0x00 both). Power is ``[0x71, 0x23|0x24, 0x0F,
sum]`` and the state query ``[0x81, 0x8A, 0x8B, sum]`` returns 14 bytes. Channel ``w`` is warm
white, ``c`` cool white. See docs/protocols/magic-home.md.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

from core.errors import RigError
from drivers.lights.base import LightBase, colour_and_white, to_byte
from drivers.transports.base import NotAnsweringError, Transport

PORT = 5577
CHANNELS = ("r", "g", "b", "c", "w")
POWER_ON, POWER_OFF = 0x23, 0x24
MODE_COLOURS, MODE_WHITES, MODE_BOTH = 0xF0, 0x0F, 0x00
STATE_REPLY_LEN = 14


def with_checksum(body: bytes) -> bytes:
    return body + bytes([sum(body) & 0xFF])


def levels_message(levels: Mapping[str, float], mode: int, persist: bool) -> bytes:
    r, g, b, c, w = (to_byte(levels.get(name, 0.0)) for name in CHANNELS)
    return with_checksum(bytes([0x31 if persist else 0x41, r, g, b, w, c, mode, 0x0F]))


def power_message(on: bool) -> bytes:
    return with_checksum(bytes([0x71, POWER_ON if on else POWER_OFF, 0x0F]))


STATE_QUERY = with_checksum(bytes([0x81, 0x8A, 0x8B]))


def parse_state(reply: bytes) -> dict[str, Any]:
    if len(reply) != STATE_REPLY_LEN or reply[0] != 0x81 or with_checksum(reply[:-1]) != reply:
        raise RigError(
            f"malformed Magic Home state reply {reply.hex(' ')}",
            "the device may use another LEDENET variant; try driver `manual`",
        )
    return {
        "model_num": f"{reply[1]:#04x}",
        "power": "on" if reply[2] == POWER_ON else "off",
        "firmware": reply[10],
        "levels_rgbwc": list(reply[6:10]) + [reply[11]],
    }


class MagicHomeLight(LightBase):
    """``exclusive_white``: bulbs that show either colour or white, never both (most RGBCW
    bulbs) get mode 0xF0/0x0F, and illuminations mixing the two are refused."""

    driver_name = "magic-home"

    def __init__(
        self,
        transport: Transport,
        illuminations: Mapping[str, Mapping[str, float]] | None = None,
        settle_s: float = 0.0,
        persist: bool = True,
        exclusive_white: bool = False,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        super().__init__(CHANNELS, illuminations, settle_s, transport, sleep)
        self.transport: Transport = transport
        self.persist = persist
        self.exclusive_white = exclusive_white
        if exclusive_white:
            for name, levels in self.illuminations.items():
                self._mode(levels, f"illumination {name!r}")
        self.state = self.query_state()
        self._powered = self.state["power"] == "on"

    def query_state(self) -> dict[str, Any]:
        self.transport.flush_input()
        self.transport.write(STATE_QUERY)
        try:
            return parse_state(self.transport.read_exactly(STATE_REPLY_LEN, "the state reply"))
        except NotAnsweringError as error:
            raise RigError(
                f"{error.problem}", "check the bulb's IP address and that it is a Magic Home device"
            ) from error

    def _mode(self, levels: Mapping[str, float], what: str) -> int:
        colour, white = colour_and_white(levels)
        if not self.exclusive_white:
            return MODE_BOTH
        if colour and white:
            raise RigError(
                f"{what} mixes colour and white channels, which this bulb cannot show together",
                "use only r/g/b or only c/w, or set `exclusive_white: false` if it can",
            )
        return MODE_WHITES if white else MODE_COLOURS

    def _apply(self, levels: dict[str, float]) -> None:
        mode = self._mode(levels, "levels")
        if not self._powered:
            self.transport.write(power_message(True))
            self._powered = True
        self.transport.write(levels_message(levels, mode, self.persist))

    def _off(self) -> None:
        self.transport.write(power_message(False))
        self._powered = False

    def _identity(self) -> dict[str, Any]:
        return {"model_num": self.state["model_num"], "firmware": self.state["firmware"]}
