"""The tiny external scene the bench tests capture: spot painted with the chart, two
Sunwayfoto lamps, a Nikon D700, one ring at 30° stepping to 0.8× and 1.2× the radius."""

from __future__ import annotations

from bench.external_scene import SceneSpec

TINY = SceneSpec(
    "smoke",
    "spot.obj",
    {"L1": "Sunwayfoto.LED.FL96.at.3000K", "L2": "Sunwayfoto.LED.FL96.at.5500K"},
    "Nikon D700",
    (0.8, 1.2),
    (30.0,),
)
