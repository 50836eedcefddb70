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

from collections.abc import Mapping
from typing import Any

import numpy as np

from calibration.defaults import cie_illuminant, illumination_spd
from core.errors import RigError
from drivers.sim.config_keys import reject_unknown_keys
from drivers.sim.light import SimLight

KEYS = ("level", "spd", "distance_m")


def room_spd(conf: Mapping[str, Any] | None, light: SimLight, radius_m: float) -> np.ndarray | None:
    """The room light's SPD on the grid, scaled as the module docstring says (None: no room
    light configured or level 0)."""
    if not conf:
        return None
    if not isinstance(conf, Mapping):
        raise RigError("sim.ambient is not a mapping", "write e.g. `ambient: {level: 0.1}`")
    reject_unknown_keys(conf, KEYS, "sim.ambient")
    try:
        level = float(conf.get("level", 0.0))
        distance = float(conf.get("distance_m", radius_m))
    except (TypeError, ValueError) as error:
        raise RigError(
            f"sim.ambient: level/distance_m must be numbers ({error})", "e.g. `level: 0.1`"
        ) from error
    if level < 0 or distance <= 0:
        raise RigError(
            f"sim.ambient: level {level} must be ≥ 0 and distance_m {distance} > 0",
            "use e.g. `level: 0.1` (10 % of the bulb)",
        )
    if level == 0:
        return None
    bulb = np.mean(
        [illumination_spd(v, light.channel_spds).sum() for v in light.illuminations.values()]
    )
    room = cie_illuminant(str(conf.get("spd", "A")))
    return np.asarray(room * (level * bulb / distance**2 / room.sum()))
