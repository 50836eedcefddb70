"""The simulator's white reference: the ColorChecker's white patch of the ``chart`` scene, seen
head-on by a one-view rig with the light at the camera."""

from __future__ import annotations

from typing import TYPE_CHECKING

from calibration import defaults
from calibration.grid import DEFAULT_GRID
from drivers.protocols import WhiteReference
from drivers.sim.scene import make_scene

if TYPE_CHECKING:
    from drivers.sim.rig import SimRig

DEFAULT_DISTANCE_M = 0.5
PATCH_SIDE_M = 0.020  # the central part of the white patch the default region covers


def chart_reference(
    rig: SimRig, distance_m: float | None, region: tuple[int, int, int, int] | None
) -> WhiteReference:
    """A chart rig with ``rig``'s reference camera and seed, ``distance_m`` from the patch."""
    names, patches = defaults.colorchecker_reflectances(DEFAULT_GRID)
    white = next(i for i, n in enumerate(names) if n.lower().startswith("white"))
    chart = make_scene("chart")
    centre = chart.vertices[chart.patch == white].mean(axis=0)
    distance = distance_m or DEFAULT_DISTANCE_M
    config = {
        "scene": "chart",
        "views": 1,
        "light_offset_m": [0.0, 0.0, 0.0],
        "camera": dict(rig.reference_camera),
        "trajectory": {
            "elevations_deg": [90.0],
            "radius_m": distance,
            "target_m": [float(c) for c in centre],
        },
    }
    chart_rig = type(rig)(config, rig.seed)  # a rig like this one, looking at the chart
    if region is None:  # the patch's centre as the camera sees it
        side = max(2, int(0.6 * chart_rig.intrinsics.K[0, 0] * PATCH_SIDE_M / distance) // 2 * 2)
        cx, cy = chart_rig.intrinsics.width // 2, chart_rig.intrinsics.height // 2
        region = (cx - side // 2, cy - side // 2, cx + side // 2, cy + side // 2)
    return WhiteReference(
        chart_rig.camera,
        chart_rig.light,
        distance,
        patches[white],
        f"sim chart patch '{names[white]}'",
        region,
        chart_rig.close,
    )
