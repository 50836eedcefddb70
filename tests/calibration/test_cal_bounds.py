"""Physically valid reflectance: the bounded QP, the projection, the bounded estimator and band."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from calibration import defaults
from calibration.basis import SpectralBasis, pca_basis
from calibration.bounds import (
    ROUND_OFF,
    bounded_band,
    bounded_quadratic,
    grey_weights,
    project,
    violation,
)
from calibration.estimation import estimate_reflectance
from core.errors import RigError


def _value(x: np.ndarray, H: np.ndarray, f: np.ndarray) -> float:
    return float(0.5 * x @ H @ x - f @ x)


def _slsqp(H: np.ndarray, f: np.ndarray, B: np.ndarray, upper: float) -> np.ndarray:
    """An independent solver of the same QP (SciPy's SLSQP) for comparison."""
    rows = [{"type": "ineq", "fun": lambda x: B @ x}]
    if np.isfinite(upper):
        rows.append({"type": "ineq", "fun": lambda x: upper - B @ x})
    res = minimize(
        lambda x: 0.5 * x @ H @ x - f @ x,
        grey_weights(B, 0.0, upper),
        jac=lambda x: H @ x - f,
        constraints=rows,
        method="SLSQP",
        options={"ftol": 1e-15, "maxiter": 1000},
    )
    return res.x


def test_projection_is_the_nearest_valid_spectrum(basis: SpectralBasis) -> None:
    rng = np.random.default_rng(1)
    alpha = basis.project(np.full(31, 0.5)) + 0.6 * rng.standard_normal((400, 8))
    out = project(alpha, basis.B)
    assert (violation(alpha, basis.B) > 0).mean() > 0.3  # the test holds invalid rows
    assert violation(out, basis.B).max() <= ROUND_OFF
    inside = violation(alpha, basis.B) <= ROUND_OFF
    np.testing.assert_array_equal(out[inside], alpha[inside])
    np.testing.assert_array_equal(project(out, basis.B), out)  # a projection is idempotent
    B = basis.B
    for k in np.flatnonzero(~inside)[:6]:
        ref = _slsqp(B.T @ B, B.T @ B @ alpha[k], B, 1.0)
        ours = np.sum((B @ (out[k] - alpha[k])) ** 2)
        theirs = np.sum((B @ (ref - alpha[k])) ** 2)
        assert ours <= theirs + 1e-9
        np.testing.assert_allclose(out[k], ref, atol=1e-5)


def test_general_quadratic_matches_an_independent_solver(basis: SpectralBasis) -> None:
    rng = np.random.default_rng(2)
    B = basis.B
    for upper in (1.0, np.inf):
        m = rng.standard_normal((6, 8))
        H = m.T @ m + 0.05 * np.eye(8)  # few observations: an ill-conditioned estimator
        f = H @ (basis.project(np.linspace(-0.3, 1.4, 31)) + 0.2 * rng.standard_normal(8))
        ours = bounded_quadratic(H, f[None], B, 0.0, upper)[0]
        ref = _slsqp(H, f, B, upper)
        assert violation(ours[None], B, 0.0, upper)[0] <= ROUND_OFF
        best = _value(ref, H, f)
        assert _value(ours, H, f) <= best + 1e-9 * (1 + abs(best))


def test_per_row_hessians_and_a_feasible_start(basis: SpectralBasis) -> None:
    rng = np.random.default_rng(3)
    B = basis.B
    m = rng.standard_normal((50, 6, 8))
    H = m.transpose(0, 2, 1) @ m + 0.1 * np.eye(8)
    target = basis.project(np.full(31, 0.5)) + 0.8 * rng.standard_normal((50, 8))
    f = np.einsum("pij,pj->pi", H, target)
    cold = bounded_quadratic(H, f, B)
    warm = bounded_quadratic(H, f, B, start=cold)  # a start at the answer stays there
    np.testing.assert_allclose(warm, cold, atol=1e-9)
    assert violation(cold, B).max() <= ROUND_OFF
    for k in range(0, 50, 10):
        ref = _slsqp(H[k], f[k], B, 1.0)
        best = _value(ref, H[k], f[k])
        assert _value(cold[k], H[k], f[k]) <= best + 1e-9 * (1 + abs(best))


def test_non_finite_rows_stay_nan(basis: SpectralBasis) -> None:
    f = np.array([[np.nan] * 8, list(basis.project(np.full(31, 2.0)))])
    out = bounded_quadratic(np.eye(8), f, basis.B)
    assert np.all(np.isnan(out[0]))
    assert violation(out[1:], basis.B).max() <= ROUND_OFF


def test_a_basis_without_a_valid_grey_is_refused() -> None:
    # one component that is zero at the short wavelengths: no grey fits inside (0, 1)
    ramp = np.clip(np.linspace(-1, 1, 31), 0, None)[None]
    with pytest.raises(RigError, match="cannot represent a grey"):
        grey_weights(pca_basis(ramp, 1).B)


def test_estimator_answers_inside_the_bounds(basis: SpectralBasis, responses: np.ndarray) -> None:
    rng = np.random.default_rng(4)
    chips = defaults.training_reflectances()
    dark, bright = chips[np.argsort(chips.mean(axis=1))[[0, -1]]]
    truth = np.stack([dark, np.clip(bright * 1.2, 0, 1)] * 50)
    rgb = np.einsum("knl,pl->pkn", responses, truth)
    rgb *= 1 + 0.03 * rng.standard_normal(rgb.shape)
    _, free = estimate_reflectance(rgb, responses, basis, bounds=None)
    assert free.min() < 0 or free.max() > 1  # the unbounded estimate leaves the range here
    _, bounded = estimate_reflectance(rgb, responses, basis)
    assert bounded.min() >= -ROUND_OFF and bounded.max() <= 1 + ROUND_OFF
    shading = np.ones(rgb.shape[:2])
    _, weighted = estimate_reflectance(rgb, responses, basis, shading=shading)
    np.testing.assert_allclose(weighted, bounded, atol=1e-8)  # both paths, one answer

    # the bounded answer fits the data no worse than clipping the unbounded one would
    def misfit(r: np.ndarray) -> float:
        return float(np.sum((np.einsum("knl,pl->pkn", responses, r) - rgb) ** 2))

    assert misfit(bounded) <= misfit(np.clip(free, 0, 1)) * (1 + 1e-9)


def test_unknown_scale_keeps_only_the_lower_bound(
    basis: SpectralBasis, responses: np.ndarray
) -> None:
    truth = np.tile(np.linspace(0.05, 0.9, 31), (3, 1))
    rgb = 7.0 * np.einsum("knl,pl->pkn", responses, truth)  # 7× too bright: shading unknown
    _, est = estimate_reflectance(rgb, responses, basis, fit_scale=True)
    np.testing.assert_allclose(est.max(axis=1), 1.0)
    assert est.min() >= -ROUND_OFF


def test_band_is_the_shortest_95_percent_inside_the_range() -> None:
    from scipy.stats import truncnorm

    r = np.array([0.0, 0.01, 0.5, 0.99, 1.0, 0.1, 0.3, 0.95])
    s = np.array([0.05, 0.05, 0.05, 0.05, 0.05, 2.0, 0.5, 0.3])
    low, high = bounded_band(r, s)
    assert np.all(low >= 0) and np.all(high <= 1) and np.all(low <= r) and np.all(high >= r)
    a, b = (0 - r) / s, (1 - r) / s
    held = truncnorm.cdf(high, a, b, loc=r, scale=s) - truncnorm.cdf(low, a, b, loc=r, scale=s)
    np.testing.assert_allclose(held, 0.95, atol=1e-9)
    # shortest: moving the band by a little either way holds less
    for shift in (-1e-3, 1e-3):
        lo, hi = np.clip(low + shift, 0, 1), np.clip(high + shift, 0, 1)
        moved = truncnorm.cdf(hi, a, b, loc=r, scale=s) - truncnorm.cdf(lo, a, b, loc=r, scale=s)
        assert np.all(moved <= held + 1e-12)
    np.testing.assert_allclose([low[2], high[2]], [0.5 - 1.96 * 0.05, 0.5 + 1.96 * 0.05], atol=1e-4)
    low, high = bounded_band(np.array([0.3]), np.array([np.nan]))
    assert np.isnan(low[0]) and np.isnan(high[0])
    low, high = bounded_band(np.array([0.9]), np.array([0.1]), upper=np.inf)
    assert high[0] > 1.0  # a relative scale has no upper bound


def test_a_singular_quadratic_still_gives_a_valid_answer(basis: SpectralBasis) -> None:
    # three observations of eight weights and no prior: H has rank 3, a KKT system can be
    # singular; the answer must still be finite, valid and no worse than the start
    rng = np.random.default_rng(6)
    m = rng.standard_normal((40, 3, 8))
    H = m.transpose(0, 2, 1) @ m
    f = np.einsum("pij,pj->pi", H, basis.project(np.full(31, 1.4)) + rng.standard_normal((40, 8)))
    out = bounded_quadratic(H, f, basis.B, unconstrained=np.full((40, 8), 5.0))
    assert np.all(np.isfinite(out)) and violation(out, basis.B).max() <= ROUND_OFF
    grey = grey_weights(basis.B)
    value = np.einsum("pi,pij,pj->p", out, H, out) / 2 - np.einsum("pi,pi->p", f, out)
    start = grey @ H @ grey / 2 - f @ grey
    assert np.all(value <= start + 1e-9)
