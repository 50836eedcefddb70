"""The coverage bar: evenly spread views fill every cell of their ring, whatever their count."""

from __future__ import annotations

import numpy as np
import pytest

from rig.capture.coverage import MAX_CELLS, coverage_hint, ring_bar
from rig.profile import Trajectory


def staggered(views: int, elevations: tuple[float, ...]) -> list[tuple[float, float]]:
    """As the simulated rig places them: rings staggered by half a step, azimuths read back
    from camera centres (so off by rounding, 35.99999... for 36)."""
    per_ring = np.array_split(np.arange(views), len(elevations))
    out = []
    for k, (elevation, ring) in enumerate(zip(elevations, per_ring, strict=True)):
        for i in range(len(ring)):
            a = np.radians(360.0 * (i + 0.5 * k) / len(ring))
            out.append((float(np.degrees(np.arctan2(np.sin(a), np.cos(a))) % 360.0), elevation))
    return out


def bar(line: str) -> str:
    return line.split("0°[", 1)[1].split("]360°", 1)[0]


@pytest.mark.parametrize("views", [10, 20, 24, 30])
def test_a_ring_of_evenly_spread_views_leaves_no_cell_empty(views: int) -> None:
    directions = staggered(views, (30.0, 50.0))
    ring = [v for v, (_, el) in enumerate(directions) if el == 30.0]
    cells = ring_bar(directions, ring, ring[0])
    assert " " not in cells and len(set(cells)) == 1, cells
    second = [v for v, (_, el) in enumerate(directions) if el == 50.0]
    assert set(ring_bar(directions, ring + second, second[0])) == {"█"}


def test_the_bar_fills_one_cell_per_view_in_plan_order() -> None:
    directions = staggered(20, (30.0, 50.0))  # the demo's plan: 10 views a ring, 36° apart
    for done in range(1, 10):
        cells = bar(coverage_hint(directions, list(range(done)), done))
        assert cells == "█" * done + " " * (10 - done)


def test_the_profiles_planned_directions_fill_the_bar() -> None:
    trajectory = Trajectory(elevations_deg=(15.0, 40.0, 65.0))
    directions = [trajectory.view_direction(v, 40) for v in range(40)]
    first_ring = [v for v, (_, el) in enumerate(directions) if el == 15.0]
    assert set(bar(coverage_hint(directions, first_ring, first_ring[-1]))) == {"█"}


def test_a_long_ring_groups_planned_azimuths_into_equal_cells() -> None:
    directions = [(360.0 * v / 48, 20.0) for v in range(48)]
    cells = ring_bar(directions, list(range(48)), 0)
    assert len(cells) <= MAX_CELLS and set(cells) == {"█"}
    half = ring_bar(directions, list(range(0, 48, 2)), 0)  # every other view: still even
    assert set(half) == {"█"}
