"""Simulated RGBCW bulb: named channels with SPDs, named illuminations, readable state.

The simulated camera reads :meth:`SimLight.spd` and :attr:`SimLight.position` at capture time,
so a frame shows exactly the illumination that was set — the same contract a real bulb has.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from calibration.defaults import default_illuminations, illumination_spd, rgbcw_channel_spds
from core.errors import RigError


class SimLight:
    """A point light with channels ``r, g, b, c, w`` (or those of ``channel_spds``)."""

    def __init__(
        self,
        channel_spds: Mapping[str, np.ndarray] | None = None,
        illuminations: Mapping[str, Mapping[str, float]] | None = None,
        serial: str = "SIM-LIGHT-0001",
    ) -> None:
        spds = dict(channel_spds) if channel_spds is not None else rgbcw_channel_spds()
        self.channel_spds = {k: np.asarray(v, dtype=float) for k, v in spds.items()}
        self.channels: tuple[str, ...] = tuple(self.channel_spds)
        self.illuminations: Mapping[str, Mapping[str, float]] = dict(
            illuminations if illuminations is not None else default_illuminations()
        )
        self.serial = serial
        self.levels: dict[str, float] = {}
        self.illumination: str | None = None
        self.position = np.zeros(3)  # world, metres; the rig moves it with the camera plate

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "light",
            "model": "spectral-rig simulated RGBCW bulb",
            "serial": self.serial,
            "transport": "sim",
            "channels": list(self.channels),
        }

    def close(self) -> None:
        self.off()

    def set_levels(self, levels: Mapping[str, float]) -> None:
        """Set channel levels in [0, 1]; channels not named are off."""
        spd_check = {k: float(v) for k, v in levels.items()}
        if spd_check:
            illumination_spd(spd_check, self.channel_spds)  # validates names and ranges
        self.levels = spd_check
        self.illumination = None

    def set_illumination(self, name: str) -> None:
        if name not in self.illuminations:
            raise RigError(
                f"sim light has no illumination {name!r}",
                f"use one of {', '.join(self.illuminations)} or define it in the profile",
            )
        self.set_levels(self.illuminations[name])
        self.illumination = name

    def off(self) -> None:
        self.levels = {}
        self.illumination = None

    def spd(self) -> np.ndarray:
        """Current emitted SPD on the grid (zeros when off)."""
        if not any(self.levels.values()):
            return np.zeros_like(next(iter(self.channel_spds.values())))
        return illumination_spd(self.levels, self.channel_spds)
