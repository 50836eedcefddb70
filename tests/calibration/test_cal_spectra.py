"""Resampling onto the grid and validation of spectra."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.grid import DEFAULT_GRID, SpectralGrid
from calibration.spectra import resample, second_difference_matrix, validate_spectrum
from core.errors import RigError

GRID_W = DEFAULT_GRID.wavelengths


def smooth(w: np.ndarray) -> np.ndarray:
    return 0.4 + 0.3 * np.sin(w / 40.0) + 0.2 * np.exp(-0.5 * ((w - 560) / 45) ** 2)


def test_identity_on_grid() -> None:
    values = smooth(GRID_W)
    np.testing.assert_array_equal(resample(GRID_W, values), values)


def test_coarser_source_interpolates_smooth_spectrum() -> None:
    w = np.arange(380.0, 781.0, 5.0)
    np.testing.assert_allclose(resample(w, smooth(w)), smooth(GRID_W), atol=2e-4)


def test_round_trip_fine_grid_and_back() -> None:
    fine = SpectralGrid(400, 700, 1)
    up = resample(GRID_W, smooth(GRID_W), fine)
    assert up.shape == (301,)
    np.testing.assert_allclose(up[::10], smooth(GRID_W), atol=1e-12)  # grid points kept
    back = resample(fine.wavelengths, up, DEFAULT_GRID, band_average=False)
    np.testing.assert_allclose(back, smooth(GRID_W), atol=1e-12)


def test_irregular_source_and_multiple_columns() -> None:
    rng = np.random.default_rng(0)
    w = np.sort(rng.uniform(395, 705, 90))
    values = np.stack([smooth(w), 2 * smooth(w), np.ones_like(w)], axis=1)
    out = resample(w, values)
    assert out.shape == (31, 3)
    np.testing.assert_allclose(out[:, 0], smooth(GRID_W), atol=2e-3)
    np.testing.assert_allclose(out[:, 1], 2 * out[:, 0], rtol=1e-9)
    np.testing.assert_allclose(out[:, 2], 1.0, atol=1e-9)


def test_dense_noisy_data_is_band_averaged() -> None:
    w = np.arange(350.0, 750.0, 0.5)
    noise = 0.02 * np.random.default_rng(1).standard_normal(w.size)
    out = resample(w, smooth(w) + noise)
    # box averaging over 10 nm (21 samples) divides the noise by ~4.6
    assert np.max(np.abs(out - smooth(GRID_W))) < 0.02


def test_small_negative_noise_is_clipped() -> None:
    w = np.arange(390.0, 711.0, 5.0)
    v = np.exp(-0.5 * ((w - 550) / 30) ** 2)
    v[2] = -0.01  # 400 nm, on the grid
    out = resample(w, v)
    assert abs(out[0]) < 1e-12 and out.min() >= 0.0


def test_extrapolation_only_when_asked() -> None:
    w = np.arange(400.0, 681.0, 10.0)
    with pytest.raises(RigError, match="covers 400–680 nm"):
        resample(w, np.ones_like(w), source="sigma.csv")
    out = resample(w, np.linspace(0.1, 1, w.size), extrapolate=True)
    assert out[-1] == pytest.approx(1.0) and out[-2] == pytest.approx(1.0)


def test_extrapolated_data_off_the_grid_is_sampled_at_the_grid() -> None:
    # starts inside the grid at a wavelength that is not a grid point (a 3 nm spectrometer)
    w = np.arange(403.0, 695.0, 3.0)
    out = resample(w, smooth(w), extrapolate=True, band_average=False)
    inside = (GRID_W >= w[0]) & (GRID_W <= w[-1])
    np.testing.assert_allclose(out[inside], smooth(GRID_W[inside]), atol=1e-3)
    assert out[0] == pytest.approx(smooth(w[0])) and out[-1] == pytest.approx(smooth(w[-1]))


@pytest.mark.parametrize(
    ("w", "v", "message"),
    [
        ([400, 500, 500, 600, 700], [1, 1, 1, 1, 1], "duplicate wavelength 500"),
        ([400, 600, 500, 650, 700], [1, 1, 1, 1, 1], "not increasing"),
        ([400, 500, np.nan, 650, 700], [1, 1, 1, 1, 1], "wavelengths contain NaN"),
        ([400, 500, 600, 650, 700], [1, np.inf, 1, 1, 1], "NaN or inf at 500 nm"),
        ([400, 500, 600, 650, 700], [1, 1, -0.5, 1, 1], "negative power/sensitivity"),
        ([400, 500, 600], [1, 1, 1], "only 3 samples"),
        ([400, 500, 600, 650, 700], [0, 0, 0, 0, 0], "all zeros"),
        ([400, 500, 600, 650, 700], [1, 1, 1], "5 wavelengths but values"),
        ([450, 500, 600, 650, 700], [1, 1, 1, 1, 1], "grid needs 400–700 nm"),
    ],
)
def test_validation_errors_name_the_source(w: list[float], v: list[float], message: str) -> None:
    with pytest.raises(RigError, match=message) as info:
        resample(np.array(w, float), np.array(v, float), source="lamp.csv")
    assert "lamp.csv" in str(info.value) and info.value.fix


def test_validate_keeps_signed_values_when_asked() -> None:
    _, v = validate_spectrum([400, 410, 420, 430], [-1, 0, 1, 2], nonnegative=False)
    assert v[:, 0].tolist() == [-1, 0, 1, 2]


def test_second_difference_matrix() -> None:
    d = second_difference_matrix(6)
    assert d.shape == (4, 6)
    x = np.arange(6.0)
    np.testing.assert_allclose(d @ (3 + 2 * x), 0)  # lines cost nothing
    np.testing.assert_allclose(d @ x**2, 2)  # curvature 2 everywhere
    with pytest.raises(RigError):
        second_difference_matrix(2)


def test_four_even_samples_are_resampled_with_the_spline() -> None:
    """colour's Sprague interpolator needs six samples (it asserted on an import of four)."""
    out = resample([400, 500, 600, 700], [1.0, 2.0, 1.0, 1.0])
    assert out.shape == (31,) and np.all(np.isfinite(out)) and out[10] == pytest.approx(2.0)
