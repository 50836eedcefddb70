"""A microcontroller RGBCW controller speaking the line-based ``rgbcw-text/1`` protocol.

Requests and replies are ASCII lines ending in ``\\n`` (see docs/protocols/rgbcw-text.md and
the reference firmware in docs/firmware/): ``ID?`` -> ``ID model=... fw=... serial=...
channels=r,g,b,c,w``, ``SET r=0.5000 g=0.0000 ...`` -> ``OK``, ``OFF`` -> ``OK``, ``GET?`` ->
``LEVELS r=...``; errors are ``ERR <reason>``. Plain text so anyone can test it from a
serial terminal and port the firmware to any board.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from core.errors import RigError
from drivers.lights.base import DEFAULT_CHANNELS, LightBase
from drivers.transports.base import NotAnsweringError, Transport

PROTOCOL = "rgbcw-text/1"


def format_set(levels: Mapping[str, float]) -> str:
    return "SET " + " ".join(f"{name}={level:.4f}" for name, level in levels.items())


def parse_fields(text: str) -> dict[str, str]:
    """``key=value`` words (values without spaces)."""
    out = {}
    for word in text.split():
        key, sep, value = word.partition("=")
        if sep:
            out[key] = value
    return out


class RgbcwSerialLight(LightBase):
    driver_name = "rgbcw-serial"

    def __init__(
        self,
        transport: Transport,
        channels: Sequence[str] = DEFAULT_CHANNELS,
        illuminations: Mapping[str, Mapping[str, float]] | None = None,
        settle_s: float = 0.0,
        boot_tries: int = 3,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        super().__init__(channels, illuminations, settle_s, transport, sleep)
        self.transport: Transport = transport
        self.identity = self._hello(boot_tries)
        device_channels = self.identity.get("channels", "").split(",")
        missing = [c for c in self.channels if c not in device_channels]
        if missing:
            raise RigError(
                f"controller on {transport.address} has channels {self.identity.get('channels')} "
                f"but the profile uses {', '.join(missing)}",
                "fix the light's `channels:` in the profile or the firmware's channel list",
            )

    def _hello(self, tries: int) -> dict[str, str]:
        """``ID?`` with a few retries: boards that reset when the port opens need a moment."""
        last: NotAnsweringError | None = None
        for _ in range(max(1, tries)):
            self.transport.flush_input()
            self.transport.write(b"ID?\n")
            try:
                line = self._line("the ID? reply")
                while line == "READY":  # boot banner: the ID? may have been lost in the reset
                    line = self._line("the ID? reply")
            except NotAnsweringError as error:
                last = error
                continue
            if not line.startswith("ID "):
                raise RigError(
                    f"{self.transport.address} answered {line!r} to ID?",
                    f"the device does not speak {PROTOCOL}: check the port and driver",
                )
            return parse_fields(line[3:])
        assert last is not None
        raise last

    def _line(self, what: str) -> str:
        raw = self.transport.read_until(b"\n", what=what)
        return raw.decode("ascii", errors="replace").strip()

    def command(self, text: str) -> str:
        """Send one command line, return the reply line; ``ERR`` becomes a RigError."""
        self.transport.write(text.encode("ascii") + b"\n")
        reply = self._line(f"the reply to {text.split()[0]}")
        if reply.startswith("ERR"):
            raise RigError(
                f"light controller {self.transport.address} refused {text!r}: {reply[3:].strip()}",
                "check the firmware version and channel names",
            )
        return reply

    def _apply(self, levels: dict[str, float]) -> None:
        self._expect_ok(format_set(levels))

    def _off(self) -> None:
        self._expect_ok("OFF")

    def _expect_ok(self, text: str) -> None:
        reply = self.command(text)
        if reply != "OK":
            raise RigError(
                f"light controller on {self.transport.address} answered {reply!r} to {text!r}",
                f"expected OK: is the firmware {PROTOCOL}?",
            )

    def read_levels(self) -> dict[str, float]:
        """Levels the controller reports (``GET?``), for checking what it applied."""
        reply = self.command("GET?")
        if not reply.startswith("LEVELS"):
            raise RigError(f"unexpected reply {reply!r} to GET?", f"is the firmware {PROTOCOL}?")
        return {k: float(v) for k, v in parse_fields(reply[6:]).items()}

    def _identity(self) -> dict[str, Any]:
        return {"protocol": PROTOCOL, "device": dict(self.identity)}
