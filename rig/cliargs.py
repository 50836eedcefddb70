"""Numbers on the command line, bounded before a command starts.

Each flag that takes a number gets ``type=number(int, min=..., max=...)``: argparse then refuses
a value outside the range (or not finite) in its one error line, naming the flag and the
allowed range, before anything is opened, computed or written:

>>> number(int, min=6, max=1000)("1000000000")
Traceback (most recent call last):
argparse.ArgumentTypeError: 1000000000 is not allowed — allowed: a whole number in [6, 1000]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

from core.config import describe, parse_value
from core.errors import RigError
from core.text import printable

SEED_MAX = 10**9  # any seed a user would type; numpy's generators take non-negative ones
MAX_VIEWS = 1000  # = rig.profile.MAX_VIEWS (that module loads OpenCV; a test keeps them equal)


def number(
    kind: type[int] | type[float],
    *,
    min: float | None = None,
    max: float | None = None,
    above: float | None = None,
) -> Callable[[str], float]:
    """An argparse ``type``: ``kind`` (int or float) within the bounds, as
    :func:`core.config.bounded` takes them."""
    meta = {k: v for k, v in (("min", min), ("max", max), ("above", above)) if v is not None}

    def parse(text: str) -> float:
        try:
            value = int(text) if kind is int else float(text)
        except ValueError:
            value = None
        try:
            checked: float = parse_value(value, kind, "", "", meta)
        except RigError:
            raise argparse.ArgumentTypeError(
                f"{printable(text)} is not allowed — allowed: {describe(kind, meta)}"
            ) from None
        return checked

    parse.__name__ = kind.__name__  # argparse names the type in some messages
    return parse
