"""Relighting: render the reconstruction (shape + spectral reflectance) from a view or a new
camera under a point light with any illuminant, with cast shadows, as an sRGB PNG.

The image is formed with the one forward model
(:func:`reconstruct.model.render.render_image`) using,
instead of a camera's ``C^T diag(L)``, the response ``M_sRGB · x̄ȳz̄ᵀ · diag(L)``: linear sRGB
(D65 primaries, no white balance, so illuminant A looks warm) of the reflected light. Exposure
is normalised so a white reflector facing the light at the scene's distance reads ``exposure``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import colour
import cv2
import numpy as np

from calibration.colorimetry import xyz_weights
from calibration.colour_difference import illuminant
from calibration.grid import SpectralGrid
from core.config import bounded, from_mapping
from core.errors import RigError
from core.files import write_bytes_atomically
from core.lock import output_lock
from core.yamlio import read_yaml
from reconstruct.model.camera import Intrinsics, Pose, read_colmap_text
from reconstruct.model.raycast import RayCaster
from reconstruct.model.render import render_image

_XYZ_TO_SRGB = np.asarray(colour.models.RGB_COLOURSPACE_sRGB.matrix_XYZ_to_RGB, dtype=float)


@dataclass(frozen=True)
class Camera:
    intrinsics: Intrinsics
    pose: Pose


def illuminant_spd(spec: str, grid: SpectralGrid) -> np.ndarray:
    """A CIE illuminant by name (D65, A, FL2, LED-B3, …) or an SPD file on ``grid``: a CSV
    ``wavelength_nm,power`` or any format `rig calibrate import` reads (OceanView, SpectraWiz)."""
    return illuminant(spec, grid).spd


def srgb_response(spd: np.ndarray, grid: SpectralGrid) -> np.ndarray:
    """(3, N_λ): reflectance -> linear sRGB of the light it reflects under ``spd``
    (a white reflector gives Y = 1 at unit shading)."""
    w = xyz_weights(grid, spd)  # (N_λ, 3), white -> Y = 1
    return _XYZ_TO_SRGB @ w.T


def encode_srgb(linear: np.ndarray) -> np.ndarray:
    """Linear sRGB -> 8-bit gamma-encoded."""
    v = np.asarray(colour.cctf_encoding(np.clip(linear, 0.0, 1.0), function="sRGB"))
    return np.clip(np.round(v * 255.0), 0, 255).astype(np.uint8)


def write_png(path: Path, rgb8: np.ndarray) -> Path:
    """Write a relit image; into a session only while no other command writes it."""
    with output_lock(path, "rig relight"):
        path.parent.mkdir(parents=True, exist_ok=True)
        ok, png = cv2.imencode(path.suffix or ".png", cv2.cvtColor(rgb8, cv2.COLOR_RGB2BGR))
        if not ok:
            raise RigError(f"cannot encode the image for {path}", "check the image size")
        write_bytes_atomically(path, png.tobytes())
    return path


@dataclass(frozen=True)
class CameraFile:
    """A virtual camera in YAML: image size, focal length, and where it stands and looks
    (metres, world frame)."""

    width: int = bounded(min=1, max=32_768)
    height: int = bounded(min=1, max=32_768)
    focal_px: float = bounded(above=0, max=1e6)
    eye: tuple[float, float, float] = bounded(min=-1000, max=1000)
    target: tuple[float, float, float] = bounded(min=-1000, max=1000)
    up: tuple[float, float, float] = bounded((0.0, 0.0, 1.0), min=-1000, max=1000)


def load_camera_file(path: Path) -> Camera:
    """A camera from a COLMAP text model folder (its first image) or a YAML file with
    ``width, height, focal_px, eye, target`` [``up``] (metres, world frame)."""
    if path.is_dir():
        cams, images = read_colmap_text(path)
        if not images:
            raise RigError(f"{path}/images.txt lists no image", "add the camera's pose")
        cid, _, pose = images[min(images)]
        return Camera(cams[cid], pose)
    data = read_yaml(path, "camera file", "fix the YAML syntax")
    conf = from_mapping(CameraFile, data, f"camera file {path}")
    if conf.eye == conf.target:
        raise RigError(f"camera file {path}: eye and target are the same point",
                       "give a target the camera looks at from its eye")
    pose = Pose.look_at(np.asarray(conf.eye), np.asarray(conf.target), conf.up)
    return Camera(Intrinsics.pinhole(conf.width, conf.height, conf.focal_px), pose)


def relight(
    vertices: np.ndarray,
    faces: np.ndarray,
    reflectance: np.ndarray,
    wavelengths_nm: np.ndarray,
    camera: Camera,
    light_position: np.ndarray,
    illuminant: str | np.ndarray = "D65",
    exposure: float = 0.8,
    supersample: int = 2,
    caster: RayCaster | None = None,
) -> np.ndarray:
    """Linear sRGB image (H, W, 3) of the reconstruction under a point light."""
    grid = SpectralGrid.from_wavelengths(wavelengths_nm)
    spd = (
        illuminant_spd(illuminant, grid) if isinstance(illuminant, str) else np.asarray(illuminant)
    )
    response = srgb_response(spd, grid)
    light = np.asarray(light_position, dtype=float)
    distance = float(np.linalg.norm(light - vertices.mean(axis=0)))
    image, _ = render_image(
        vertices,
        faces,
        reflectance,
        camera.intrinsics,
        camera.pose,
        light,
        response * (exposure * distance**2),
        supersample=supersample,
        caster=caster,
    )
    return image
