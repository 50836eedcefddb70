"""A light the person switches by hand (any bulb with its phone app, a lamp with a dimmer).

The tool says which illumination to set and waits for Enter; typing ``q`` aborts. The input
function is a parameter so tests (and GUIs) can answer.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from core.errors import RigError
from drivers.lights.base import DEFAULT_CHANNELS, LightBase


class ManualLight(LightBase):
    driver_name = "manual"

    def __init__(
        self,
        channels: Sequence[str] = DEFAULT_CHANNELS,
        illuminations: Mapping[str, Mapping[str, float]] | None = None,
        settle_s: float = 0.0,
        ask: Callable[[str], str] = input,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        super().__init__(channels, illuminations, settle_s, None, sleep)
        self._ask = ask
        self._pending_name: str | None = None

    def set_illumination(self, name: str) -> None:
        self._pending_name = name
        try:
            super().set_illumination(name)
        finally:
            self._pending_name = None

    def _prompt(self, text: str) -> None:
        answer = self._ask(f"{text} — press Enter when done (q to abort): ")
        if answer.strip().lower() in {"q", "quit", "abort"}:
            raise RigError(
                "capture aborted at the light prompt", "run again (or resume) when ready"
            )

    def _apply(self, levels: dict[str, float]) -> None:
        shown = ", ".join(f"{k}={v:.2f}" for k, v in levels.items() if v > 0) or "all off"
        if self._pending_name:
            self._prompt(f"Set the light to illumination {self._pending_name!r} ({shown})")
        else:
            self._prompt(f"Set the light channels to {shown}")

    def _off(self) -> None:
        self._prompt("Switch the light off")

    def _identity(self) -> dict[str, Any]:
        return {"operator": "manual"}
