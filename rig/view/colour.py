"""Per-illuminant matrices that turn a reflectance spectrum into linear sRGB, so the page can
recolour the mesh for any illuminant with one (N, L) x (L, 3) product and the sRGB transfer
function — the same colour-science XYZ (:func:`calibration.colorimetry.xyz_weights`) that
:func:`calibration.colorimetry.reflectance_to_srgb` and the ΔE00 of `rig evaluate` use."""

from __future__ import annotations

from pathlib import Path

import colour
import numpy as np

from calibration.colorimetry import white_xyz, xyz_weights
from calibration.grid import SpectralGrid
from core.errors import RigError
from reconstruct.outputs.relight import illuminant_spd

DEFAULT_ILLUMINANTS = ("D65", "A", "FL2", "FL11", "LED-B3", "LED-V1")


def linear_srgb_matrix(grid: SpectralGrid, spd: np.ndarray) -> np.ndarray:
    """(L, 3) matrix M with linear sRGB = reflectance @ M under ``spd`` (white adapted to D65
    by CAT02, as :func:`calibration.colorimetry.reflectance_to_srgb`)."""
    w = xyz_weights(grid, spd)
    xy_white = colour.XYZ_to_xy(white_xyz(grid, spd))
    rows = colour.XYZ_to_sRGB(np.eye(3), illuminant=xy_white,
                              chromatic_adaptation_transform="CAT02", apply_cctf_encoding=False)
    return w @ np.asarray(rows, dtype=float)


def illuminant_matrices(names: list[str], grid: SpectralGrid) -> dict[str, np.ndarray]:
    out = {}
    for name in names:
        spd = illuminant_spd(name, grid)
        label = Path(name).stem if Path(name).suffix else name
        if spd.max() <= 0:
            raise RigError(f"illuminant {name} has no power", "give an SPD with positive values")
        out[label] = linear_srgb_matrix(grid, spd)
    return out
