"""Per-pixel reflectance estimation (basis + spectral smoothness)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration import defaults
from calibration.basis import SpectralBasis
from calibration.estimation import estimate_reflectance, response_matrices
from core.errors import RigError


def render(resp: np.ndarray, refl: np.ndarray) -> np.ndarray:
    return np.einsum("knl,pl->pkn", resp, refl)


def test_recovers_reflectance_in_basis_span(basis: SpectralBasis, responses: np.ndarray) -> None:
    rng = np.random.default_rng(5)
    alpha = 0.05 * rng.standard_normal((500, 8))
    alpha[:, 0] += 2.5
    refl = basis.reconstruct(alpha)
    est_alpha, est = estimate_reflectance(render(responses, refl), responses, basis, 0.0)
    np.testing.assert_allclose(est_alpha, alpha, atol=1e-4)
    np.testing.assert_allclose(est, refl, atol=1e-5)


def test_smoothness_keeps_two_illuminations_well_posed(
    basis: SpectralBasis, responses: np.ndarray
) -> None:
    _, refl = defaults.colorchecker_reflectances()
    resp = responses[:2]  # LED1 + LED2: 6 equations for 8 unknowns
    _, est = estimate_reflectance(render(resp, refl), resp, basis, 1e-3)
    rmse = np.sqrt(np.mean((est - refl) ** 2, axis=1))
    assert rmse.mean() < 0.06  # measured 0.047


def test_per_pixel_shading_and_missing_values(basis: SpectralBasis, responses: np.ndarray) -> None:
    rng = np.random.default_rng(6)
    alpha = 0.05 * rng.standard_normal((40, 8))
    alpha[:, 0] += 2.0
    refl = basis.reconstruct(alpha)
    shading = rng.uniform(0.2, 3.0, (40, 3))
    rgb = render(responses, refl) * shading[:, :, None]
    shading[0, 2] = 0.0  # pixel 0 not seen under LED3
    rgb[0, 2] = 123.0  # ... so this value must be ignored
    rgb[1, 1, 0] = np.nan  # pixel 1: one saturated channel
    rgb[2] = np.nan  # pixel 2: nothing usable
    est_alpha, _ = estimate_reflectance(rgb, responses, basis, 0.0, shading=shading)
    assert np.all(np.isnan(est_alpha[2]))
    ok = np.ones(40, bool)
    ok[[0, 1, 2]] = False
    np.testing.assert_allclose(est_alpha[ok], alpha[ok], atol=1e-3)
    # pixels 0 and 1 have fewer equations than unknowns but must stay finite
    assert np.all(np.isfinite(est_alpha[:2]))


def test_unknown_scale_is_normalised(basis: SpectralBasis, responses: np.ndarray) -> None:
    _, refl = defaults.colorchecker_reflectances()
    a1, r1 = estimate_reflectance(render(responses, refl), responses, basis, fit_scale=True)
    a2, r2 = estimate_reflectance(7.0 * render(responses, refl), responses, basis, fit_scale=True)
    np.testing.assert_allclose(r1.max(axis=1), 1.0)
    np.testing.assert_allclose(r1, r2, atol=1e-10)


def test_shared_and_weighted_paths_agree(basis: SpectralBasis, responses: np.ndarray) -> None:
    _, refl = defaults.colorchecker_reflectances()
    rgb = render(responses, refl)
    a_shared, _ = estimate_reflectance(rgb, responses, basis, 0.1)
    a_weighted, _ = estimate_reflectance(rgb, responses, basis, 0.1, shading=np.ones((24, 3)))
    np.testing.assert_allclose(a_shared, a_weighted, rtol=1e-8, atol=1e-10)


def test_shape_errors(basis: SpectralBasis, responses: np.ndarray) -> None:
    with pytest.raises(RigError, match="expected \\(P, 3, 3\\)"):
        estimate_reflectance(np.zeros((5, 2, 3)), responses, basis)
    with pytest.raises(RigError, match="response matrices have shape"):
        estimate_reflectance(np.zeros((5, 3, 3)), responses[:, :, :30], basis)
    with pytest.raises(RigError, match="shading has shape"):
        estimate_reflectance(np.zeros((5, 3, 3)), responses, basis, shading=np.ones((4, 3)))
    with pytest.raises(RigError, match="smoothness -1 is negative"):
        estimate_reflectance(np.zeros((5, 3, 3)), responses, basis, -1.0)
    with pytest.raises(RigError, match="not on the same grid"):
        response_matrices(np.ones((31, 3)), np.ones((2, 30)))
