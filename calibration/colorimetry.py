"""sRGB previews of spectral reflectances through colour-science.

XYZ is the CIE 1931 2° integral of reflectance × illuminant, normalised so a perfect white
reflector has Y = 1 (colour-science's integration method); the illuminant's white point is
adapted to D65 with CAT02 and encoded with the sRGB transfer function by
:func:`colour.XYZ_to_sRGB`. Vectorised: one matrix for all pixels.
"""

from __future__ import annotations

import colour
import numpy as np

from calibration.defaults import cie_illuminant
from calibration.grid import DEFAULT_GRID, SpectralGrid
from calibration.spectra import resample
from core.errors import RigError

CMFS = "CIE 1931 2 Degree Standard Observer"


def xyz_weights(
    grid: SpectralGrid = DEFAULT_GRID, illuminant: str | np.ndarray = "D65"
) -> np.ndarray:
    """(N_λ, 3) matrix W with XYZ = r @ W (perfect white → Y = 1)."""
    cmfs = colour.MSDS_CMFS[CMFS]
    xyz_bar = resample(cmfs.wavelengths, cmfs.values, grid, source=CMFS, band_average=False)
    spd = (
        cie_illuminant(illuminant, grid) if isinstance(illuminant, str) else np.asarray(illuminant)
    )
    if spd.shape != (grid.size,) or not np.all(np.isfinite(spd)) or spd.max() <= 0:
        raise RigError(
            f"illuminant SPD has shape {spd.shape} (or no power), grid needs ({grid.size},)",
            "give a CIE illuminant name (e.g. D65) or an SPD resampled onto the grid",
        )
    w = xyz_bar * spd[:, None]
    return w / w[:, 1].sum()


def reflectance_to_srgb(
    reflectance: np.ndarray,
    grid: SpectralGrid = DEFAULT_GRID,
    illuminant: str | np.ndarray = "D65",
    linear: bool = False,
) -> np.ndarray:
    """Gamma-encoded sRGB (…, 3) in [0, 1] of reflectances (…, N_λ) seen under ``illuminant``
    (white adapted to D65); ``linear``: without the sRGB transfer function (glTF colours)."""
    w = xyz_weights(grid, illuminant)
    white = w.sum(axis=0)
    xy_white = colour.XYZ_to_xy(white)
    xyz = np.asarray(reflectance, dtype=float) @ w
    srgb = colour.XYZ_to_sRGB(
        xyz,
        illuminant=xy_white,
        chromatic_adaptation_transform="CAT02",
        apply_cctf_encoding=not linear,
    )
    return np.clip(np.nan_to_num(np.asarray(srgb, dtype=float)), 0.0, 1.0)
