"""The sim's room light (``sim.ambient``): a dim, uniform environment of a CIE illuminant that
is on in every frame (lit ones and the bulb-off ``ambient`` frame), so that ambient
subtraction can be measured.

``level`` is the room light's irradiance relative to the bulb's (mean over its named
illuminations) at ``distance_m`` (default: the trajectory radius); ``spd`` names the CIE
illuminant (default ``A``, incandescent room light; e.g. ``FL2`` for fluorescent). The
environment is uniform and unoccluded: each surface point gets the same irradiance whatever its
normal (no ambient occlusion), so the term is ``level``-scaled ``C^T diag(L_room) r``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.defaults import cie_illuminant, illumination_spd
from core.config import bounded
from drivers.sim.light import SimLight


@dataclass(frozen=True)
class AmbientConfig:
    """The ``sim.ambient`` section (see the module docstring)."""

    level: float = bounded(0.0, min=0, max=100)
    spd: str = "A"
    distance_m: float | None = bounded(None, above=0, max=100)  # None: the trajectory radius


def room_spd(conf: AmbientConfig | None, light: SimLight, radius_m: float) -> np.ndarray | None:
    """The room light's SPD on the grid, scaled as the module docstring says (None: no room
    light configured or level 0)."""
    if conf is None or conf.level == 0:
        return None
    level, distance = conf.level, conf.distance_m or radius_m
    bulb = np.mean(
        [illumination_spd(v, light.channel_spds).sum() for v in light.illuminations.values()]
    )
    room = cie_illuminant(conf.spd)
    return np.asarray(room * (level * bulb / distance**2 / room.sum()))
