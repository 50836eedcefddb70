"""Spectra -> CIE XYZ -> sRGB through colour-science: the one colorimetric path of the project
(previews, the viewer, the PLY's colours and the ΔE00 of :mod:`calibration.colour_difference`).

XYZ is colour-science's CIE 1931 2° integral of reflectance × illuminant (``colour.msds_to_XYZ``,
integration method) on the spectral grid, scaled so a perfect white reflector has Y = 1. It is
linear in the reflectance, so it is kept as one (N_λ, 3) matrix for all pixels. sRGB adapts the
illuminant's white to D65 with CAT02 and encodes with the sRGB transfer function
(:func:`colour.XYZ_to_sRGB`).
"""

from __future__ import annotations

import functools

import colour
import numpy as np

from calibration.defaults import cie_illuminant
from calibration.grid import DEFAULT_GRID, SpectralGrid
from core.errors import RigError

CMFS = "CIE 1931 2 Degree Standard Observer"


def xyz_weights(
    grid: SpectralGrid = DEFAULT_GRID, illuminant: str | np.ndarray = "D65"
) -> np.ndarray:
    """(N_λ, 3) matrix W with XYZ = r @ W (perfect white → Y = 1)."""
    spd = (
        cie_illuminant(illuminant, grid) if isinstance(illuminant, str) else np.asarray(illuminant)
    )
    if spd.shape != (grid.size,) or not np.all(np.isfinite(spd)) or spd.max() <= 0:
        raise RigError(
            f"illuminant SPD has shape {spd.shape} (or no power), grid needs ({grid.size},)",
            "give a CIE illuminant name (e.g. D65) or an SPD resampled onto the grid",
        )
    return _weights(grid, tuple(float(v) for v in spd))


@functools.lru_cache(maxsize=64)
def _weights(grid: SpectralGrid, spd: tuple[float, ...]) -> np.ndarray:
    """:func:`xyz_weights` computed once per grid and SPD (read-only)."""
    shape = colour.SpectralShape(grid.start_nm, grid.stop_nm, grid.step_nm)
    sd = colour.SpectralDistribution(dict(zip(grid.wavelengths, spd, strict=True)))
    cmfs = colour.MSDS_CMFS[CMFS].copy().align(shape)  # sampled on the grid, as the spectra
    # XYZ of each unit-impulse reflectance: the rows of the linear map (colour scales Y to 100)
    rows = colour.msds_to_XYZ(
        np.eye(grid.size), cmfs=cmfs, illuminant=sd, method="Integration", shape=shape
    )
    weights = np.asarray(rows, dtype=float) / 100.0
    weights.setflags(write=False)
    return weights


def reflectance_to_xyz(
    reflectance: np.ndarray, grid: SpectralGrid = DEFAULT_GRID, illuminant: str | np.ndarray = "D65"
) -> np.ndarray:
    """CIE XYZ (…, 3) of reflectances (…, N_λ) under ``illuminant`` (perfect white → Y = 1)."""
    return np.asarray(reflectance, dtype=float) @ xyz_weights(grid, illuminant)


def white_xyz(
    grid: SpectralGrid = DEFAULT_GRID, illuminant: str | np.ndarray = "D65"
) -> np.ndarray:
    """XYZ of the perfect diffuser under ``illuminant`` (Y = 1): the white of CIELAB."""
    return xyz_weights(grid, illuminant).sum(axis=0)


def reflectance_to_srgb(
    reflectance: np.ndarray,
    grid: SpectralGrid = DEFAULT_GRID,
    illuminant: str | np.ndarray = "D65",
    linear: bool = False,
) -> np.ndarray:
    """Gamma-encoded sRGB (…, 3) in [0, 1] of reflectances (…, N_λ) seen under ``illuminant``
    (white adapted to D65); ``linear``: without the sRGB transfer function (glTF colours)."""
    xy_white = colour.XYZ_to_xy(white_xyz(grid, illuminant))
    xyz = reflectance_to_xyz(reflectance, grid, illuminant)
    srgb = colour.XYZ_to_sRGB(
        xyz,
        illuminant=xy_white,
        chromatic_adaptation_transform="CAT02",
        apply_cctf_encoding=not linear,
    )
    return np.clip(np.nan_to_num(np.asarray(srgb, dtype=float)), 0.0, 1.0)
