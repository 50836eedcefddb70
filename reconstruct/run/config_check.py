"""Type checks of the reconstruct config's sections against their dataclass defaults.

A word where a number belongs (``optimise.gamma: "abc"``, ``subdivide.max_faces: many``) or a
negative iteration count would otherwise pass into the stage and surface as an internal error,
or as a silently empty loop. Each failure is one RigError naming the section and the key.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from core.errors import RigError


def is_number(value: Any) -> bool:
    """A finite int or float (not a bool, not a string)."""
    return (
        isinstance(value, (int, float)) and not isinstance(value, bool) and bool(np.isfinite(value))
    )


def check_types(
    conf: Mapping[str, Any],
    defaults: object,
    where: str,
    low: float | None = None,
    lows: Mapping[str, float] | None = None,
) -> None:
    """Each key whose default is a bool, int or float must have that type (an int where a float
    is expected is fine) and be at least ``lows[key]`` or ``low`` when given."""
    for key, value in conf.items():
        default = getattr(defaults, key, None)
        bound = (lows or {}).get(key, low)
        if isinstance(default, bool):
            if not isinstance(value, bool):
                raise RigError(f"{where}: {key} is {value!r}", "use true or false")
        elif isinstance(default, int):
            if isinstance(value, bool) or not isinstance(value, int):
                raise RigError(f"{where}: {key} is {value!r}", "use a whole number")
            if bound is not None and value < bound:
                raise RigError(f"{where}: {key} is {value}", f"use a whole number >= {bound:g}")
        elif isinstance(default, float):
            if not is_number(value):
                raise RigError(f"{where}: {key} is {value!r}", "use a finite number")
            if bound is not None and value < bound:
                raise RigError(f"{where}: {key} is {value}", f"use a number >= {bound:g}")
