"""Simulated RGB camera: renders the scene with the one forward model, adds sensor noise,
mosaics (Bayer) and writes a real DNG.

Per frame: linear image ``y`` (forward model, anti-aliased) -> times the lens's fall-off when
``vignetting`` asks for one (:class:`VignettingConfig`) -> raw
``black + y · (white − black) · exposure_s · iso / 100`` (docs/architecture.md, Linear image
values, read backwards) -> shot noise (Poisson in electrons) + read noise (Gaussian, DN) ->
rounded, clipped to ``[0, white]`` (saturation is real) -> Bayer mosaic -> DNG. Geometry
(primary hits, shadow rays) is cached per pose so several illuminations of one view cost one trace.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import zlib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Literal

import colour
import numpy as np

from calibration.defaults import (
    DEFAULT_CAMERA,
    camera_sensitivity,
    cie_illuminant,
    colorchecker_reflectances,
)
from calibration.grid import DEFAULT_GRID
from calibration.spectra import resample
from core.config import bounded, from_mapping
from core.errors import RigError
from drivers.protocols import CapturedFrame
from drivers.sim.dng import write_dng
from drivers.sim.light import SimLight
from drivers.sim.projector import SimProjector
from drivers.sim.scene import Scene
from reconstruct.model import forward, render
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.raycast import RayCaster


@dataclass(frozen=True)
class VignettingConfig:
    """The ``camera.vignetting`` section: a lens that darkens towards the corners. ``cos4``:
    natural fall-off, cos⁴ of the angle off the axis; ``extra``: a lens's own fall-off on top,
    ``1 − extra · r²`` with r = 1 at the corners."""

    cos4: bool = False
    extra: float = bounded(0.0, min=0.0, max=0.95)

    def gain(self, intrinsics: Intrinsics) -> np.ndarray:
        """The fall-off (H, W) at pixel centres, 1 on the axis."""
        width, height = intrinsics.width, intrinsics.height
        fx = float(intrinsics.K[0, 0])
        cx, cy = float(intrinsics.K[0, 2]), float(intrinsics.K[1, 2])
        x = (np.arange(width) + 0.5) - cx
        y = (np.arange(height) + 0.5) - cy
        d2 = y[:, None] ** 2 + x[None, :] ** 2
        gain = np.ones((height, width))
        if self.cos4:
            gain *= (fx**2 / (fx**2 + d2)) ** 2
        return gain * (1.0 - self.extra * d2 / ((width**2 + height**2) / 4.0))


@dataclass(frozen=True)
class GlossConfig:
    """The ``sim.gloss`` section: a neutral GGX lobe on the whole object (a varnish or glaze):
    ``specular`` its reflectance at normal incidence, ``alpha`` its roughness."""

    specular: float = bounded(0.04, min=0.0, max=1.0)
    alpha: float = bounded(0.2, above=0.0, max=1.0)


@dataclass(frozen=True)
class SensorConfig:
    """The ``camera`` section of a sim profile (defaults: a 640x480 14-bit RGGB camera)."""

    width: int = bounded(640, min=32, max=16_384)
    height: int = bounded(480, min=32, max=16_384)
    focal_px: float = bounded(800.0, above=0, max=1e6)
    black_level: int = bounded(512, min=0, max=65535)
    white_level: int = bounded(16383, min=1, max=65535)
    pattern: Literal["RGGB", "BGGR", "GRBG", "GBRG"] = "RGGB"
    exposure_s: float = bounded(1.0, above=0, max=3600)
    iso: float = bounded(250.0, above=0, max=1e6)
    gain_e_per_dn: float = bounded(1.0, above=0, max=1e6)  # at ISO 100; halves per ISO doubling
    read_noise_dn: float = bounded(2.0, min=0, max=1e6)
    supersample: int = bounded(2, min=1, max=8)
    normals: render.NormalMode = "smooth"
    sensitivity: str = DEFAULT_CAMERA
    make: str = "spectral-rig"
    model: str = "SimCam 14-bit"
    serial: str = "SIM-CAM-0001"
    vignetting: VignettingConfig | None = None  # None: an ideal lens

    def __post_init__(self) -> None:
        if self.width % 2 or self.height % 2:
            raise RigError(
                f"sim.camera: image size {self.width}x{self.height}",
                "use even width and height (a whole Bayer mosaic)",
            )
        if self.black_level >= self.white_level:
            raise RigError(
                f"sim.camera: black {self.black_level} / white {self.white_level}",
                "use black_level < white_level",
            )

    @property
    def intrinsics(self) -> Intrinsics:
        return Intrinsics.pinhole(self.width, self.height, self.focal_px)


def _cfa_channel(pattern: str, height: int, width: int) -> np.ndarray:
    """Channel index (0 R, 1 G, 2 B) of every sensor pixel for a 2x2 pattern like ``RGGB``."""
    code = np.array(["RGB".index(c) for c in pattern.upper()]).reshape(2, 2)
    return np.tile(code, (height // 2, width // 2))


def colour_matrix(sensitivity: np.ndarray) -> np.ndarray:
    """DNG ColorMatrix1 (XYZ -> camera, D65) fitted on the ColorChecker by least squares."""
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz_bar = resample(cmfs.wavelengths, cmfs.values, DEFAULT_GRID, band_average=False)
    d65 = cie_illuminant("D65")
    refl = colorchecker_reflectances()[1]
    xyz = refl @ (xyz_bar * d65[:, None])
    cam = refl @ (sensitivity * d65[:, None])
    M = np.linalg.lstsq(xyz, cam, rcond=None)[0].T  # cam = M xyz
    white = M @ (xyz_bar * d65[:, None]).sum(axis=0)
    return M / white.max()


class SimCamera:
    """Implements :class:`drivers.protocols.Camera`; the rig sets the pose per view."""

    def __init__(
        self,
        scene: Scene,
        light: SimLight,
        projector: SimProjector | None,
        sensor: SensorConfig | None = None,
        seed: int = 0,
        caster: RayCaster | None = None,
        ground: render.GroundPlane | None = None,
    ) -> None:
        self.scene = scene
        self.ground = ground
        self._reflectance = render.with_ground(scene.reflectance, ground)
        self.light = light
        self.projector = projector
        self.sensor = sensor or SensorConfig()
        self.intrinsics = self.sensor.intrinsics
        self.seed = seed
        self.sensitivity = camera_sensitivity(self.sensor.sensitivity)
        self.caster = caster or RayCaster(scene.vertices, scene.faces)
        self._vertex_normals = render.vertex_normals(scene.vertices, scene.faces)
        self._color_matrix = colour_matrix(self.sensitivity)
        self.pose = Pose.look_at(np.array([0.0, -0.5, 0.0]), np.zeros(3))
        self._hits: tuple[bytes, render.ViewHits] | None = None
        self._weights: dict[tuple[bytes, ...], np.ndarray] = {}
        self._rgb: dict[bytes, np.ndarray] = {}
        self.ambient_spd: np.ndarray | None = None  # room light in every frame (sim.ambient)
        self.bulb_radius_m = 0.0  # a bulb with a size (sim.light_diameter_m); 0: a point
        self.gloss: GlossConfig | None = None  # a neutral specular lobe (sim.gloss)

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "camera",
            "model": f"{self.sensor.make} {self.sensor.model}",
            "serial": self.sensor.serial,
            "transport": "sim",
            "resolution": [self.sensor.width, self.sensor.height],
            "sensitivity": self.sensor.sensitivity,
        }

    def close(self) -> None:
        self._hits = None
        self._weights.clear()

    def sensitivity_name(self) -> str:
        """The built-in sensitivity this camera renders with (:class:`NamedSensitivity`)."""
        return self.sensor.sensitivity

    def set_pose(self, pose: Pose) -> None:
        self.pose = pose

    def set_exposure(self, exposure_s: float | None = None, iso: float | None = None) -> None:
        """Change shutter time and/or ISO for the following captures."""
        changes: dict[str, float] = {}
        if exposure_s is not None:
            changes["exposure_s"] = float(exposure_s)
        if iso is not None:
            changes["iso"] = float(iso)
        self.sensor = from_mapping(
            SensorConfig, {**_as_dict(self.sensor), **changes}, "sim config", "sim.camera"
        )

    # --- rendering -------------------------------------------------------------------------

    def _view_hits(self) -> render.ViewHits:
        key = _key(self.pose.R, self.pose.t)
        if self._hits is None or self._hits[0] != key:
            hits = render.trace_view(
                self.caster,
                self.intrinsics,
                self.pose,
                self.sensor.supersample,
                "flat" if self.sensor.normals == "flat" else "smooth",
                self._vertex_normals,
                ground=self.ground,
            )
            self._hits = (key, hits)
            self._weights.clear()
        return self._hits[1]

    def render_linear(self) -> np.ndarray:
        """Noise-free linear image ``y`` (H, W, 3) of what the camera sees now."""
        hits = self._view_hits()
        terms: list[tuple[np.ndarray, np.ndarray]] = []
        spd = self.light.spd()
        if spd.any():
            key: tuple[bytes, ...] = (b"light", _key(self.light.position))
            if key not in self._weights:
                self._weights[key] = render.light_weight(
                    self.caster, hits, self.light.position, self.bulb_radius_m
                )
            terms.append((self._weights[key], self._vertex_rgb(spd)))
            if self.gloss is not None:
                terms.append((self._gloss_weight(hits, key), self._white_rgb(spd)))
        proj = self.projector
        if proj is not None and proj.image is not None:
            key = (
                b"proj",
                _key(proj.pose.R, proj.pose.t),
                hashlib.sha1(proj.image.tobytes()).digest(),
            )
            if key not in self._weights:
                self._weights[key] = render.projector_weights(
                    self.caster, hits, proj.image, proj.intrinsics, proj.pose
                )
            w = self._weights[key]
            terms += [
                (w[:, k], self._vertex_rgb(proj.primary_spds[c])) for k, c in enumerate("rgb")
            ]
        if self.ambient_spd is not None:
            terms.append((np.ones(len(hits.index)), self._vertex_rgb(self.ambient_spd)))
        return render.shade_vertex_rgb(hits, terms)

    def _gloss_weight(self, hits: render.ViewHits, light_key: tuple[bytes, ...]) -> np.ndarray:
        """The gloss lobe's weight per hit for the light now on (none on the ground)."""
        key = (b"gloss", *light_key[1:])
        if key not in self._weights:
            assert self.gloss is not None
            weight = render.specular_weight(
                hits, self.light.position, self.pose.center, self._weights[light_key],
                self.gloss.specular, self.gloss.alpha,
            )
            if hits.on_ground is not None:
                weight = np.where(hits.on_ground, 0.0, weight)
            self._weights[key] = weight
        return self._weights[key]

    def _white_rgb(self, spd: np.ndarray) -> np.ndarray:
        """``C^T L`` per vertex: a highlight is the lamp's own colour (dichromatic model)."""
        key = b"white" + _key(spd)
        if key not in self._rgb:
            resp = forward.response_matrix(self.sensitivity, spd)
            self._rgb[key] = render.vertex_rgb(np.ones_like(self._reflectance), resp)
        return self._rgb[key]

    def _vertex_rgb(self, spd: np.ndarray) -> np.ndarray:
        """Per-vertex ``(C^T L) r`` (plus the ground's paper and ink), cached per SPD (a
        capture uses a few illuminations)."""
        key = _key(spd)
        if key not in self._rgb:
            if len(self._rgb) > 16:
                self._rgb.clear()
            resp = forward.response_matrix(self.sensitivity, spd)
            self._rgb[key] = render.vertex_rgb(self._reflectance, resp)
        return self._rgb[key]

    def expose(self, linear: np.ndarray, stem: str) -> np.ndarray:
        """Linear image -> noisy, clipped uint16 Bayer mosaic (seeded by the seed and ``stem``)."""
        s = self.sensor
        rng = np.random.default_rng([self.seed, zlib.crc32(stem.encode())])
        channel = _cfa_channel(s.pattern, s.height, s.width)
        rows, cols = np.indices((s.height, s.width))
        y = linear[rows, cols, channel]
        span = s.white_level - s.black_level
        signal_dn = np.maximum(y, 0.0) * span * s.exposure_s * s.iso / 100.0
        gain = s.gain_e_per_dn * 100.0 / s.iso  # electrons per DN at this ISO
        electrons = rng.poisson(signal_dn * gain)
        dn = electrons / gain + rng.normal(0.0, s.read_noise_dn, y.shape)
        raw = np.rint(s.black_level + dn)
        return np.clip(raw, 0, s.white_level).astype(np.uint16)

    def capture(self, out_dir: Path, stem: str) -> CapturedFrame:
        """Render, expose and write ``out_dir/stem.dng``."""
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        linear = self.render_linear()
        if self.sensor.vignetting is not None:
            linear = linear * self.sensor.vignetting.gain(self.intrinsics)[..., None]
        mosaic = self.expose(linear, stem)
        s = self.sensor
        spd = self.light.spd()
        neutral = self.sensitivity.T @ (spd if spd.any() else cie_illuminant("D65"))
        path = out_dir / f"{stem}.dng"
        write_dng(
            path,
            mosaic,
            pattern=s.pattern,
            black_level=s.black_level,
            white_level=s.white_level,
            exposure_s=s.exposure_s,
            iso=s.iso,
            make=s.make,
            model=s.model,
            serial=s.serial,
            color_matrix=self._color_matrix,
            as_shot_neutral=neutral / neutral.max() if neutral.max() > 0 else np.ones(3),
        )
        return CapturedFrame(
            paths=(path,),
            exposure_s=s.exposure_s,
            iso=s.iso,
            camera_serial=s.serial,
            timestamp=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
            extra={
                "black_level": s.black_level,
                "white_level": s.white_level,
                "cfa_pattern": s.pattern,
                "illumination": self.light.illumination,
                "saturated_fraction": float(np.mean(mosaic >= s.white_level)),
            },
        )


def _key(*arrays: np.ndarray) -> bytes:
    return b"".join(np.ascontiguousarray(a, dtype=float).tobytes() for a in arrays)


def _as_dict(conf: SensorConfig) -> dict[str, Any]:
    return {f.name: getattr(conf, f.name) for f in fields(conf)}
