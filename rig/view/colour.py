"""Per-illuminant matrices that turn a reflectance spectrum into linear sRGB, so the page can
recolour the mesh for any illuminant with one (N, L) x (L, 3) product and the sRGB transfer
function — the same numbers :func:`calibration.colorimetry.reflectance_to_srgb` gives."""

from __future__ import annotations

from pathlib import Path

import colour
import numpy as np

from calibration.colorimetry import xyz_weights
from calibration.defaults import cie_illuminant
from calibration.errors import RigError
from calibration.grid import SpectralGrid
from calibration.importers import read_spectrum
from calibration.spectra import resample

DEFAULT_ILLUMINANTS = ("D65", "A", "FL2", "FL11", "LED-B3", "LED-V1")


def linear_srgb_matrix(grid: SpectralGrid, spd: np.ndarray) -> np.ndarray:
    """(L, 3) matrix M with linear sRGB = reflectance @ M under ``spd`` (white adapted to D65
    by CAT02, as :func:`calibration.colorimetry.reflectance_to_srgb`)."""
    w = xyz_weights(grid, spd)
    xy_white = colour.XYZ_to_xy(w.sum(axis=0))
    rows = colour.XYZ_to_sRGB(np.eye(3), illuminant=xy_white,
                              chromatic_adaptation_transform="CAT02", apply_cctf_encoding=False)
    return w @ np.asarray(rows, dtype=float)


def encode_srgb(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function on clipped linear values (what the page's JS does)."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def illuminant_spd(name_or_file: str, grid: SpectralGrid) -> tuple[str, np.ndarray]:
    """A CIE illuminant by name, or an SPD file (CSV ``wavelength_nm,power`` or any format the
    calibration importers read), on ``grid``."""
    path = Path(name_or_file)
    if path.suffix and path.is_file():
        spectrum = read_spectrum(path)
        power = spectrum.column(None, "light")
        return path.stem, resample(spectrum.wavelengths_nm, power, grid, source=str(path))
    return name_or_file, cie_illuminant(name_or_file, grid)


def illuminant_matrices(names: list[str], grid: SpectralGrid) -> dict[str, np.ndarray]:
    out = {}
    for name in names:
        label, spd = illuminant_spd(name, grid)
        if spd.max() <= 0:
            raise RigError(f"illuminant {name} has no power", "give an SPD with positive values")
        out[label] = linear_srgb_matrix(grid, spd)
    return out
