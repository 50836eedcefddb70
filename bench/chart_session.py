"""A capture session of a flat ColorChecker rendered by Mitsuba 3, for the chart check.

The sim's ``chart`` card (24 patches of 20 mm with the true ColorChecker reflectances, near
black borders), lit by measured lamp SPDs and seen by a measured camera, captured by the
project's own capture with the external renderer's camera (:mod:`bench.external_session`), so
``rig check-chart SESSION`` reads it exactly like a capture.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.console import Console

from bench.external_render import ShadingRenderer
from bench.external_scene import SceneSpec, camera_ssf, lamp_spd
from bench.external_session import (
    ExternalCamera,
    Size,
    exposure_scale,
    write_profile,
    write_store,
)
from core.errors import RigError
from drivers.sim.scene import make_scene

CHART_SPEC = SceneSpec(
    "chart",
    "",  # no mesh file: the sim's chart card
    {"L1": "Sunwayfoto.LED.FL96.at.3000K", "L2": "Sunwayfoto.LED.FL96.at.5500K"},
    "Nikon D700",
    (1.0,),
    (70.0,),
)


@dataclass(frozen=True)
class ChartSize:
    """A small render: two views, the card about 240 px wide."""

    width: int = 640
    height: int = 480
    focal_px: float = 800.0
    views: int = 2
    radius_m: float = 0.5
    spp: int = 4


def build_chart_session(
    out: Path, data: Path, spec: SceneSpec = CHART_SPEC, size: ChartSize = ChartSize()
) -> Path:
    """Render and write ``out/session`` (and ``out/scene``, ``out/store``)."""
    from rig.capture import run_capture
    from rig.capture.devices import open_devices

    scene = make_scene("chart")
    scene_dir = out / "scene"
    scene.save(scene_dir)
    ssf = camera_ssf(data, spec.camera)
    lamps = {n: lamp_spd(data, lamp) for n, lamp in spec.lamps.items()}
    scale = exposure_scale(lamps, ssf, size.radius_m)
    lamps = {n: spd * scale for n, spd in lamps.items()}
    store = out / "store"
    write_store(store, lamps, ssf, spec)
    profile = out / "profile.yaml"
    render_size = Size(
        width=size.width, height=size.height, focal_px=size.focal_px, views=size.views,
        radius_m=size.radius_m, spp=size.spp, ambient=0.0,
    )  # fmt: skip
    write_profile(profile, spec, render_size, scene_dir, store)

    def open_rig(prof: Any, seed: int, ask: Any) -> Any:
        devices = open_devices(prof, seed, ask)
        sim = getattr(devices.camera, "rig", None)
        if sim is None:
            raise RigError(f"{profile}: the external camera needs the sim rig (driver: sim)")
        renderer = ShadingRenderer(
            sim.scene.vertices, sim.scene.faces, sim.scene.patch, sim.intrinsics, size.spp
        )
        devices.camera.close()
        devices.camera = ExternalCamera(sim.scene, sim.light, sim, renderer, lamps, ssf, None, seed)
        devices.names["camera"] = "external (Mitsuba 3)"
        return devices

    session = out / "session"
    run_capture(
        profile, session, yes=True, seed=spec.seed, console=Console(file=io.StringIO()),
        open_rig=open_rig,
        notes=f"chart scene: {spec.camera}, lamps {', '.join(spec.lamps.values())}",
    )  # fmt: skip
    return session
