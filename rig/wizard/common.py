"""What every step of the wizard shares: the prompt, the date, switching the light."""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable

import numpy as np
from rich.console import Console

from core.errors import RigError
from rig.capture.devices import RigDevices, device_errors
from rig.profile import Profile

Ask = Callable[[str], str]


def today() -> str:
    return dt.date.today().isoformat()


def step(ask: Ask | None, console: Console, text: str) -> None:
    """Say what the person does next; wait for Enter when there is a person."""
    if ask is None:
        console.print(text, highlight=False)
    else:
        ask(f"{text} — press Enter ")


def set_light(devices: RigDevices, profile: Profile, name: str | None) -> None:
    """Switch to illumination ``name`` (None: off), on the light or, without one, as a
    uniform colour on the projector."""
    light = devices.light
    if light is None:
        if devices.projector is None:
            raise RigError(f"{profile.source} has no light or projector", "add devices.light")
        levels = profile.illuminations.get(name or "", {})
        rgb = np.array([levels.get(c, 0.0) for c in "rgb"])
        projector = devices.projector
        image = np.broadcast_to(rgb, (projector.height, projector.width, 3)).copy()
        with device_errors("projector", devices.names.get("projector", "?"), "show a colour"):
            projector.show(image) if name else projector.blank()
        return
    with device_errors("light", devices.names.get("light", "?"), f"switch to {name or 'off'}"):
        if name is None:
            light.off()
        else:
            light.set_levels(profile.illuminations[name])


def halve_exposure(camera: object, exposure_s: float, what: str) -> None:
    """Halve the exposure after a saturated ``what``, or say how to when the camera's exposure
    is not set from here."""
    setter = getattr(camera, "set_exposure", None)
    if setter is None:
        raise RigError(
            f"the {what} is saturated",
            "shorten the exposure (camera_settings.exposure_s) and run again",
        )
    setter(exposure_s / 2)
