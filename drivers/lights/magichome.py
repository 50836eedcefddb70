"""Magic Home / flux LED Wi-Fi bulbs and controllers (LEDENET protocol, TCP port 5577).

The bytes come from flux_led (extra ``flux``), the maintained implementation of the protocol:
its protocol classes build and check every message, and its model database says which protocol
a device speaks, from the model number and firmware version in the state reply. This driver
writes levels over the project's own transport (so the tests script it byte by byte) in the
five-channel 9-byte LEDENET message, or in the 25-byte one of newer RGBCW bulbs (colour as HSV
in whole percent, white as a temperature and a brightness: coarser, but an illumination is a
fixed setting whose spectrum is measured, so only repeatability matters), and refuses devices
that speak another protocol. Channel ``w`` is warm white, ``c`` cool white. See
docs/protocols/magic-home.md.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from core.errors import MissingDependencyError, RigError
from drivers.lights.base import LightBase, colour_and_white, to_byte
from drivers.transports.base import NotAnsweringError, Transport

if TYPE_CHECKING:
    from flux_led.protocol import ProtocolLEDENET9Byte

PORT = 5577
CHANNELS = ("r", "g", "b", "c", "w")


def five_channel_protocols() -> tuple[ProtocolLEDENET9Byte, ...]:
    """flux_led's LEDENET protocols whose levels message carries the five channels r, g, b,
    warm white and cool white, the plain 9-byte one first; their state query and 14-byte reply
    are those of every LEDENET device with a checksum."""
    try:
        from flux_led import protocol
    except ImportError as error:
        raise MissingDependencyError("flux-led", "flux", "needed for Magic Home lights") from error
    classes = (
        protocol.ProtocolLEDENET9Byte,
        protocol.ProtocolLEDENET9ByteAutoOn,
        protocol.ProtocolLEDENET9ByteDimmableEffects,
        protocol.ProtocolLEDENET25Byte,
    )
    # flux_led marks methods @abstractmethod without ABCMeta; it instantiates these itself
    return tuple(cls() for cls in classes)  # type: ignore[abstract]


def protocol_for(model_num: int, firmware: int) -> ProtocolLEDENET9Byte:
    """The protocol flux_led's model database gives this device (models it does not know are
    taken to be 9-byte controllers); a RigError unless its levels carry the five channels."""
    from flux_led.models_db import get_model

    supported = {protocol.name: protocol for protocol in five_channel_protocols()}
    model = get_model(model_num, next(iter(supported)))
    name = model.protocol_for_version_num(firmware)
    if name not in supported:
        raise RigError(
            f"Magic Home model {model_num:#04x} ({model.description}, firmware {firmware}) "
            f"speaks flux_led's {name} protocol, not a five-channel one this driver writes",
            "use a five-channel (RGB/WW/CW) LEDENET controller, or driver `manual`",
        )
    return supported[name]


def parse_state(reply: bytes, protocol: ProtocolLEDENET9Byte) -> dict[str, Any]:
    """The state reply, its length, head and checksum checked by flux_led."""
    if not protocol.is_valid_state_response(reply):
        raise RigError(
            f"malformed Magic Home state reply {reply.hex(' ')}",
            "the device may use another LEDENET variant; try driver `manual`",
        )
    state = protocol.named_raw_state(reply)
    return {
        "model_num": f"{state.model_num:#04x}",
        "power": "on" if state.power_state == protocol.on_byte else "off",
        "firmware": state.version_number,
        "levels_rgbwc": [
            state.red,
            state.green,
            state.blue,
            state.warm_white,
            state.cool_white,
        ],
    }


class MagicHomeLight(LightBase):
    """``exclusive_white``: bulbs that show either colour or white, never both (most RGBCW
    bulbs) get flux_led's colours-only/whites-only write modes, and illuminations mixing the two
    are refused."""

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
                self._check_exclusive(levels, f"illumination {name!r}")
        self.protocol = five_channel_protocols()[0]
        self.state = self.query_state()
        self.protocol = protocol_for(int(self.state["model_num"], 16), self.state["firmware"])
        self._powered = self.state["power"] == "on"

    def query_state(self) -> dict[str, Any]:
        self.transport.flush_input()
        self.transport.write(bytes(self.protocol.construct_state_query()))
        try:
            reply = self.transport.read_exactly(
                self.protocol.state_response_length, "the state reply"
            )
        except NotAnsweringError as error:
            raise RigError(
                f"{error.problem}", "check the bulb's IP address and that it is a Magic Home device"
            ) from error
        return parse_state(reply, self.protocol)

    def _check_exclusive(self, levels: Mapping[str, float], what: str) -> None:
        colour, white = colour_and_white(levels)
        if colour and white:
            raise RigError(
                f"{what} mixes colour and white channels, which this bulb cannot show together",
                "use only r/g/b or only c/w, or set `exclusive_white: false` if it can",
            )

    def _write_mode(self, levels: Mapping[str, float]) -> int:
        modes = self.protocol.level_write_modes
        if not self.exclusive_white:
            return modes.ALL
        self._check_exclusive(levels, "levels")
        return modes.WHITES if colour_and_white(levels)[1] else modes.COLORS

    def _apply(self, levels: dict[str, float]) -> None:
        mode = self._write_mode(levels)
        if not self._powered:
            self.transport.write(bytes(self.protocol.construct_state_change(True)))
            self._powered = True
        r, g, b, c, w = (to_byte(levels.get(name, 0.0)) for name in CHANNELS)
        for message in self.protocol.construct_levels_change(self.persist, r, g, b, w, c, mode):
            self.transport.write(bytes(message))

    def _off(self) -> None:
        self.transport.write(bytes(self.protocol.construct_state_change(False)))
        self._powered = False

    def _identity(self) -> dict[str, Any]:
        return {"model_num": self.state["model_num"], "firmware": self.state["firmware"]}
