"""A capture session of an externally rendered scene, written by the project's own capture.

``rig.capture.run_capture`` runs unchanged on a sim profile (trajectory, light on the camera
plate, manifest, calibration snapshot, ground truth, true poses in ``poses/``); only the
camera is swapped for :class:`ExternalCamera`, which composes Mitsuba's per-patch shading
images with the measured lamp and camera spectra and hands the linear image to the sim
camera's own exposure (shot + read noise, clipping, Bayer mosaic) and DNG writer. So
``rig reconstruct SESSION`` reads it exactly like a capture. Real optics (``Size.optics``):
the renderer's bulb and gloss, and lens fall-off as a gain on the linear image before exposure.
With ``Size.flat_field`` the fall-off is calibrated first as a user would: the wizard's own
flat-field step photographs white cards that Mitsuba renders through the same lens, and the
session's decode divides by the fitted flat field.
"""

from __future__ import annotations

import argparse
import io
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from rich.console import Console

from bench.external_optics import IDEAL, Optics, falloff_gain
from bench.external_render import ShadingRenderer, compose
from bench.external_scene import SceneSpec, camera_ssf, lamp_spd, load_mesh, painted_scene
from calibration.grid import DEFAULT_GRID
from calibration.store import CalibrationStore
from core.errors import RigError
from drivers.protocols import WhiteCard
from drivers.sim.camera import SimCamera, colour_matrix
from drivers.sim.light import SimLight
from drivers.sim.scene import Scene
from reconstruct.model import forward

# The bulb's channel levels the two (or three) illuminations are switched with; each name is
# mapped to its measured lamp SPD in the session's calibration store.
_LEVELS = ({"c": 1.0}, {"w": 1.0}, {"r": 1.0, "g": 1.0, "b": 1.0})
CAMERA_NAME = "external-camera"
FLAT_FIELD_NAME = "external-lens"
FLAT_FIELD_POSITIONS = 4  # the wizard's default


@dataclass(frozen=True)
class Size:
    """Image size, focal length, views, mesh size and render quality of a benchmark run."""

    width: int = 800
    height: int = 600
    focal_px: float = 1100.0
    views: int = 40
    object_m: float = 0.2
    radius_m: float = 0.5
    spp: int = 16
    ambient: float = 0.0  # ambient level relative to the bulb (0: no room light)
    ambient_frames: bool = True  # with a room light: capture an ambient frame per view
    optics: Optics = IDEAL  # real-optics effects (default: ideal optics)
    flat_field: bool = False  # calibrate the lens's fall-off with the wizard's flat-field step


class ExternalCamera(SimCamera):
    """The sim camera with its image formation replaced by Mitsuba's shading images: the
    scene's patches carry the ColorChecker's reflectances, or ``reflectances`` (K, n)."""

    def __init__(
        self,
        scene: Scene,
        light: SimLight,
        rig: Any,
        renderer: ShadingRenderer,
        lamps: Mapping[str, np.ndarray],
        ssf: np.ndarray,
        ambient: np.ndarray | None,
        seed: int,
        reflectances: np.ndarray | None = None,
    ) -> None:
        super().__init__(scene, light, None, rig.sensor, seed)
        self.sensitivity = ssf
        self._color_matrix = colour_matrix(ssf)
        self.rig = rig
        self.renderer = renderer
        self.lamps = dict(lamps)
        # the profile switches lamp i with _LEVELS[i] (write_profile); the wizard sets levels
        self._levels = {name: _LEVELS[i] for i, name in enumerate(lamps)}
        chart = _chart()[1] if reflectances is None else np.atleast_2d(reflectances)
        chart = chart[: renderer.n_patches]
        if renderer.n_images > renderer.n_patches:  # the specular shading: neutral, white
            chart = np.vstack([chart, np.ones(chart.shape[1])])
        self._patch_rgb = {
            name: chart @ forward.response_matrix(ssf, spd).T for name, spd in lamps.items()
        }
        self._ambient = None if ambient is None else chart @ forward.response_matrix(ssf, ambient).T
        optics = renderer.optics
        self._gain = falloff_gain(renderer.intrinsics, optics) if optics.has_falloff else None

    def render_linear(self) -> np.ndarray:
        """Σ_k shading_k · Cᵀ diag(L) ρ_k for the lamp now on (and the ambient light)."""
        view = self.rig.view
        pose = self.rig.poses[view]
        name = self._lamp()
        shape = (self.sensor.height, self.sensor.width, 3)
        image = np.zeros(shape)
        if name is not None:
            shading = self.renderer.render(pose, self.rig.light_positions[view])
            image += compose(shading, self._patch_rgb[name])
        if self._ambient is not None:
            image += compose(self.renderer.render(pose, None), self._ambient)
        if self._gain is not None:  # lens fall-off: the sensor-side effect, after rendering
            image *= self._gain[..., None]
        return image


    def _lamp(self) -> str | None:
        """The measured lamp now on, by illumination name or by the levels that switch it."""
        name = self.light.illumination
        if name is None and any(self.light.levels.values()):
            name = next((n for n, lv in self._levels.items() if lv == self.light.levels), None)
            if name is None:
                raise RigError(
                    f"external camera: light levels {self.light.levels} switch no measured lamp"
                )
        if name is not None and name not in self._patch_rgb:
            raise RigError(f"external camera: illumination {name!r} has no measured lamp")
        return name

    def white_card(self, position: int) -> WhiteCard:
        """The sim rig's white card (its place, the light on the plate, this lens) rendered
        by Mitsuba, matte whatever the object's gloss: the wizard's flat-field target."""
        from drivers.sim.white_card import white_card

        card = white_card(self.rig, position)
        card_rig = card.camera.rig  # type: ignore[attr-defined]
        scene = card_rig.scene
        renderer = ShadingRenderer(
            scene.vertices,
            scene.faces,
            np.zeros(len(scene.vertices), dtype=np.int64),
            card_rig.intrinsics,
            self.renderer.spp,
            self.renderer.cache,
            optics=replace(self.renderer.optics, gloss_reflectance=0.0),
        )
        white = scene.reflectance.mean(axis=0, keepdims=True)
        camera = ExternalCamera(
            scene, card_rig.light, card_rig, renderer, self.lamps, self.sensitivity, None,
            self.seed, white,
        )
        return replace(card, camera=camera)


def _chart() -> tuple[list[str], np.ndarray]:
    from calibration.defaults import colorchecker_reflectances

    return colorchecker_reflectances()


def write_store(
    root: Path, lamps: Mapping[str, np.ndarray], ssf: np.ndarray, spec: SceneSpec
) -> None:
    """The session's calibration store: the measured lamps and camera, on the grid."""
    store = CalibrationStore(root)
    wl = DEFAULT_GRID.wavelengths
    for name, spd in lamps.items():
        store.add_light(name, wl, spd, {"source": f"shared data lamp {spec.lamps[name]}"})
    store.add_camera(CAMERA_NAME, wl, ssf, {"source": f"camspec {spec.camera}"})


def write_profile(path: Path, spec: SceneSpec, size: Size, scene_dir: Path, store: Path) -> None:
    """A sim profile for the scene: plate light 10 cm right of the lens (and the bulb's
    diameter), the spec's trajectory, the measured calibration (and flat field), true poses."""
    names = list(spec.lamps)
    profile = {
        "name": f"external-{spec.name}",
        "description": "external-renderer benchmark scene (Mitsuba 3)",
        "devices": {"light": {"driver": "sim"}, "camera": {"driver": "sim"}},
        "camera_settings": {"exposure_s": 1.0, "iso": 100},
        "light_mount": {
            "type": "plate",
            "offset_m": [0.1, 0.0, 0.0],
            # the bulb's size, as its user would enter it (None: the point light rendered)
            "diameter_m": 2 * size.optics.bulb_radius_m or None,
        },
        "illuminations": {n: dict(_LEVELS[i]) for i, n in enumerate(names)},
        "plan": {
            "views": size.views,
            "illuminations": "all",
            "ambient": size.ambient > 0 and size.ambient_frames,
            "trajectory": {
                "elevations_deg": list(spec.elevations_deg),
                "distance_factors": list(spec.distance_factors),
            },
        },
        "calibration": {
            "store": str(store),
            "camera": CAMERA_NAME,
            **({"flat_field": FLAT_FIELD_NAME} if size.flat_field else {}),
        },
        "poses": "known",
        "sim": {
            "scene": str(scene_dir),
            "trajectory": {"radius_m": size.radius_m},
            "camera": {
                "width": size.width,
                "height": size.height,
                "focal_px": size.focal_px,
                "sensitivity": "Canon EOS 5D Mark II",
            },
        },
    }
    path.write_text(yaml.safe_dump(profile, sort_keys=False))


def exposure_scale(lamps: Mapping[str, np.ndarray], ssf: np.ndarray, nearest_m: float) -> float:
    """Lamp scale that puts a white patch facing the light at ``nearest_m`` at 0.8 of the
    sensor's range in its brightest channel (a well exposed capture, highlights kept)."""
    peak = max(float(np.max(ssf.T @ spd)) for spd in lamps.values())
    return 0.8 * nearest_m**2 / peak


def build_session(
    spec: SceneSpec,
    size: Size,
    out: Path,
    data: Path,
    cache: Path | None,
    on_frame: Callable[[Any], None] | None = None,
) -> Path:
    """Render and write the session ``out/session`` (and ``out/scene``, ``out/store``)."""
    from rig.capture import run_capture
    from rig.capture.devices import open_devices

    mesh = load_mesh(data / "meshes" / spec.mesh, size.object_m)
    scene = painted_scene(spec.name, mesh, 24, spec.seed)
    scene_dir = out / "scene"
    scene.save(scene_dir)
    ssf = camera_ssf(data, spec.camera)
    lamps = {n: lamp_spd(data, lamp) for n, lamp in spec.lamps.items()}
    nearest = size.radius_m * min(spec.distance_factors) - size.object_m / 4
    scale = exposure_scale(lamps, ssf, nearest)
    lamps = {n: spd * scale for n, spd in lamps.items()}
    ambient = None
    if size.ambient > 0:  # uniform sky: an open white patch gets `ambient` × the bulb at radius_m
        ambient = lamp_spd(data, spec.ambient_lamp) * scale * size.ambient / size.radius_m**2
    store = out / "store"
    write_store(store, lamps, ssf, spec)
    profile = out / "profile.yaml"
    write_profile(profile, spec, size, scene_dir, store)

    def open_rig(prof: Any, seed: int, ask: Any) -> Any:
        devices = open_devices(prof, seed, ask)
        sim = getattr(devices.camera, "rig", None)  # the simulated rig the sim camera is part of
        if sim is None:
            raise RigError(f"{profile}: the external camera needs the sim rig (driver: sim)")
        renderer = ShadingRenderer(
            sim.scene.vertices,
            sim.scene.faces,
            sim.scene.patch,
            sim.intrinsics,
            size.spp,
            cache,
            optics=size.optics,
        )
        devices.camera.close()
        devices.camera = ExternalCamera(
            sim.scene, sim.light, sim, renderer, lamps, ssf, ambient, seed
        )
        devices.names["camera"] = "external (Mitsuba 3)"
        return devices

    if size.flat_field:
        calibrate_flat_field(profile, store, open_rig, spec.seed)
    session = out / "session"
    run_capture(
        profile,
        session,
        yes=True,
        seed=spec.seed,
        console=Console(file=io.StringIO()),
        open_rig=open_rig,
        on_frame=on_frame,
        notes=f"external-renderer scene {spec.name}: {spec.mesh}, {spec.camera}, "
        f"lamps {', '.join(spec.lamps.values())}",
    )
    return session


def calibrate_flat_field(
    profile_path: Path, store: Path, open_rig: Callable[[Any, int, Any], Any], seed: int
) -> None:
    """`rig calibrate`'s flat-field step on the external camera's white cards, stored as the
    profile's flat field."""
    from rig.profile import load_profile
    from rig.wizard.flat_field import measure_flat_field

    profile = load_profile(profile_path)
    devices = open_rig(profile, seed, None)
    try:
        flat = measure_flat_field(
            argparse.Namespace(flat_field_positions=FLAT_FIELD_POSITIONS),
            profile,
            devices,
            None,
            Console(file=io.StringIO()),
        )
    finally:
        devices.close()
    CalibrationStore(store).add_flat_field(FLAT_FIELD_NAME, *flat)
