"""sRGB previews agree with colour-science's own spectral → XYZ → sRGB path."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from calibration import defaults
from calibration.colorimetry import reflectance_to_srgb, xyz_weights
from calibration.grid import DEFAULT_GRID
from core.errors import RigError


@pytest.mark.filterwarnings("ignore::colour.utilities.ColourRuntimeWarning")
def test_xyz_matches_colour_integration() -> None:
    _, refl = defaults.colorchecker_reflectances()
    for patch in (0, 5, 14):
        sd = colour.SpectralDistribution(refl[patch], DEFAULT_GRID.wavelengths)
        expected = colour.sd_to_XYZ(
            sd, illuminant=colour.SDS_ILLUMINANTS["D65"], method="Integration"
        )
        np.testing.assert_allclose(refl[patch] @ xyz_weights(), expected / 100, rtol=3e-3)


def test_white_and_black() -> None:
    out = reflectance_to_srgb(np.stack([np.ones(31), np.zeros(31), np.full(31, 0.18)]))
    np.testing.assert_allclose(out[0], 1.0, atol=2e-3)
    np.testing.assert_allclose(out[1], 0.0, atol=1e-9)
    assert out[2] == pytest.approx([out[2, 0]] * 3, abs=2e-3)  # grey stays neutral
    # a perfect white stays white under illuminant A (chromatic adaptation)
    np.testing.assert_allclose(reflectance_to_srgb(np.ones(31), illuminant="A"), 1.0, atol=5e-3)


def test_colorchecker_preview_is_plausible() -> None:
    names, refl = defaults.colorchecker_reflectances()
    srgb = reflectance_to_srgb(refl.reshape(4, 6, 31))
    assert srgb.shape == (4, 6, 3) and srgb.min() >= 0 and srgb.max() <= 1
    red = srgb.reshape(24, 3)[names.index("red")]
    blue = srgb.reshape(24, 3)[names.index("blue")]
    assert red[0] > red[1] and red[0] > red[2]
    assert blue[2] > blue[0] and blue[2] > blue[1]
    w = xyz_weights()
    white = colour.XYZ_to_xy(np.ones(31) @ w)
    expected = colour.XYZ_to_sRGB(refl[0] @ w, illuminant=white)
    np.testing.assert_allclose(srgb[0, 0], np.clip(expected, 0, 1), atol=1e-9)


def test_custom_illuminant_spd_and_errors() -> None:
    flat = np.ones(31)
    np.testing.assert_allclose(reflectance_to_srgb(np.ones(31), illuminant=flat), 1.0, atol=5e-3)
    with pytest.raises(RigError, match="illuminant SPD has shape"):
        reflectance_to_srgb(np.ones(31), illuminant=np.ones(30))
