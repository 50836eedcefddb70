"""The coverage line shown before each view: which azimuths of this view's elevation ring are
done, and where this view goes.

The bar has one cell per planned azimuth of the ring (a few planned azimuths per cell when the
ring has more than ``MAX_CELLS``), centred on them: fixed-width azimuth bins would leave a
cell empty, or half full, whenever the ring's view count is no multiple of the bin count,
although the views are evenly spread.
"""

from __future__ import annotations

import math

import numpy as np

MAX_CELLS = 24
BLOCKS = " ▁▂▃▄▅▆▇█"


def ring_of(directions: list[tuple[float, float]], view: int) -> list[int]:
    """The views planned at ``view``'s elevation (to the degree), in plan order."""
    elevation = round(directions[view][1])
    return [v for v, (_, el) in enumerate(directions) if round(el) == elevation]


def ring_bar(directions: list[tuple[float, float]], done: list[int], view: int) -> str:
    """One cell per planned azimuth of ``view``'s ring, its height the views done there."""
    ring = ring_of(directions, view)
    slots = len(ring)
    cells = slots // math.ceil(slots / MAX_CELLS)
    start = directions[ring[0]][0]
    step = 360.0 / slots
    counts = np.zeros(cells, dtype=int)
    members = set(ring)
    for v in done:
        if v in members:
            # nearest planned slot (views sit on slots up to rounding), then its cell
            slot = round(((directions[v][0] - start) % 360.0) / step) % slots
            counts[slot * cells // slots] += 1
    top = max(int(counts.max()), 1)
    return "".join(BLOCKS[int(round(c / top * (len(BLOCKS) - 1)))] for c in counts)


def coverage_hint(
    directions: list[tuple[float, float]],
    done: list[int],
    view: int,
    distance_factor: float | None = None,
) -> str:
    """One line: the azimuths done on this view's elevation ring, the elevations done, and
    where this view goes (and how far, relative to the usual distance, when the plan steps
    in and out)."""
    elevations = sorted({round(directions[v][1]) for v in done})
    az, el = directions[view]
    distance = ""
    if distance_factor is not None and distance_factor != 1:
        step = "step closer" if distance_factor < 1 else "step back"
        distance = f", distance {distance_factor:g}× the usual ({step})"
    elif distance_factor is not None:
        distance = ", usual distance"
    return (
        f"coverage so far: ring {el:.0f}° azimuth 0°[{ring_bar(directions, done, view)}]360°, "
        f"elevations {elevations or '-'}; "
        f"this view: azimuth {round(az) % 360}°, elevation {el:.0f}°{distance}"
    )
