"""Per-vertex uncertainty from the final linearisation, and where it is exported."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import spearmanr

from calibration.basis import default_basis, pca_basis
from calibration.defaults import training_reflectances
from reconstruct.optimise.cost import JointCost
from reconstruct.optimise.problem_setup import build_problem
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.steps import optimise
from reconstruct.optimise.synthetic import SyntheticScene, make_scene
from reconstruct.optimise.uncertainty import (
    ReflectancePrior,
    VertexUncertainty,
    expected_error,
    reflectance_prior,
    vertex_uncertainty,
)
from reconstruct.outputs import export
from reconstruct.outputs.result import load_result
from reconstruct.run.pipeline import export_result


def _at_truth(scene: SyntheticScene) -> VertexUncertainty:
    light = scene.light_offset[None]
    problem = build_problem(scene.input(), scene.vertices, light, OptimiseSettings())
    theta = problem.pack(scene.vertices, scene.alpha, light)
    prior = reflectance_prior(scene.basis)
    return vertex_uncertainty(JointCost(problem), theta, problem.obs.per_vertex > 0, prior)


@pytest.fixture(scope="module")
def noisy() -> tuple[SyntheticScene, SyntheticScene]:
    return make_scene(3, 8, noise=0.002, seed=4), make_scene(3, 8, noise=0.004, seed=4)


def test_noise_level_is_read_from_the_residuals_and_scales_the_std(noisy):
    a, b = (_at_truth(s) for s in noisy)
    # at the truth the residuals are the noise (the basis reproduces the reflectance), summed
    # over 3M residuals but divided by the 3M − n_params degrees of freedom of a fit
    light = noisy[0].light_offset[None]
    problem = build_problem(noisy[0].input(), noisy[0].vertices, light, OptimiseSettings())
    m3 = 3 * problem.obs.count
    inflation = np.sqrt(m3 / a.dof)
    assert a.noise_std == pytest.approx(0.002 * inflation, rel=0.1)
    assert b.noise_std == pytest.approx(0.004 * inflation, rel=0.1)
    ok = np.isfinite(a.reflectance_std_gn[:, 0])
    ratio = b.reflectance_std_gn[ok] / a.reflectance_std_gn[ok]
    # twice the noise: at least twice the std (noisier colours also loosen the photometric
    # smoothness weights, so a little more)
    assert np.median(ratio) >= 0.95 * b.noise_std / a.noise_std


def test_unobserved_vertices_have_no_uncertainty_and_more_views_mean_less(noisy):
    scene = noisy[0]
    unc = _at_truth(scene)
    light = scene.light_offset[None]
    problem = build_problem(scene.input(), scene.vertices, light, OptimiseSettings())
    count = problem.obs.per_vertex
    assert unc.reflectance_std_gn is not None
    assert unc.reflectance_std.shape == unc.reflectance_std_gn.shape == scene.reflectance.shape
    assert unc.position_std_m.shape == (len(scene.vertices),)
    assert np.all(np.isnan(unc.reflectance_std_gn[count == 0]))
    seen = count > 0
    assert np.all(np.isfinite(unc.reflectance_std_gn[seen]))
    assert np.all(unc.position_std_m[seen] > 0)
    rho = spearmanr(count[seen], unc.reflectance_std_gn[seen].mean(axis=1)).statistic
    assert rho < -0.3


def test_optimise_reports_and_export_writes_the_uncertainty(tmp_path, noisy):
    scene = noisy[0]
    inp = scene.input()
    cfg = OptimiseSettings(outer_iterations=1, joint_iterations=3, light_iterations=5)
    result = optimise(inp, cfg)
    unc = result.uncertainty
    assert unc is not None
    assert np.all(np.isfinite(unc.reflectance_std[result.observed]))
    figures, report, mesh, npz, report_path = export_result(
        tmp_path, inp, result, cfg, {"reflectance_scale_absolute": True}
    )
    data = export.read_reflectance_npz(npz)
    np.testing.assert_array_equal(data["reflectance_std"], unc.reflectance_std)
    np.testing.assert_array_equal(data["position_std_m"], unc.position_std_m)
    # a vertex's colour and its band come from one vertex, itself or a settled neighbour
    src = data["colour_source"]
    np.testing.assert_array_equal(src, result.colour_source)
    np.testing.assert_array_equal(result.alpha, result.alpha[src])
    np.testing.assert_array_equal(unc.reflectance_high, unc.reflectance_high[src])
    header = mesh.read_bytes().split(b"end_header")[0].decode()
    assert "property float refl_std_400" in header and "property float position_std_m" in header
    summary = json.loads(report_path.read_text())["uncertainty"]
    assert summary["vertices_with_uncertainty"] == int(result.observed.sum())
    assert summary["reflectance_std_median"] > 0
    assert tmp_path / "uncertainty.png" in figures
    # physically valid: the spectra and their 95 % band inside [0, 1], the band holding them
    assert result.reflectance.min() >= 0.0 and result.reflectance.max() <= 1.0
    low, high = data["reflectance_low"], data["reflectance_high"]
    seen = result.observed
    assert np.all(low[seen] >= 0.0) and np.all(high[seen] <= 1.0)
    assert np.all(low[seen] <= result.reflectance[seen] + 1e-12)
    assert np.all(high[seen] >= result.reflectance[seen] - 1e-12)
    band = load_result(tmp_path).reflectance_band
    assert band is not None
    np.testing.assert_array_equal(band[0], low)


def test_expected_error_is_the_posterior_spread_plus_the_estimates_offset_from_its_mean():
    # a linear Gaussian model per vertex: 6 measurements (2 illuminations × 3 channels) of
    # [t, α] (N_b = 8), so two α directions are seen by the prior only
    rng = np.random.default_rng(3)
    nb, k = 8, 5
    prior = ReflectancePrior(
        mean=rng.normal(size=nb),
        cov=np.cov(rng.normal(size=(50, nb)), rowvar=False),
        truncation_var=np.zeros(31),
    )
    J = rng.normal(size=(k, 6, 1 + nb))
    y = rng.normal(size=(k, 6))
    est = rng.normal(size=(k, 1 + nb))  # any estimate, e.g. one the regularisers pulled
    grad = np.einsum("kri,kr->ki", J, np.einsum("kri,ki->kr", J, est) - y)
    got = expected_error(J.transpose(0, 2, 1) @ J, grad, est[:, 1:], prior)
    # brute force: the posterior of y = J θ + N(0, 1) with N(μ, Σ) on α, by least squares on
    # the whitened stack [J; L⁻¹ [0 I]] (Σ = L Lᵀ); t has no prior
    L = np.linalg.cholesky(prior.cov)
    W = np.hstack([np.zeros((nb, 1)), np.linalg.inv(L)])
    for i in range(k):
        A = np.vstack([J[i], W])
        b = np.concatenate([y[i], np.linalg.solve(L, prior.mean)])
        mean = np.linalg.lstsq(A, b, rcond=None)[0]
        cov = np.linalg.inv(A.T @ A)
        off = est[i] - mean
        np.testing.assert_allclose(got[i], cov + np.outer(off, off), rtol=1e-8, atol=1e-10)
    # at the posterior mean there is no offset: only the posterior spread is left
    mean0 = np.linalg.lstsq(
        np.vstack([J[0], W]), np.concatenate([y[0], np.linalg.solve(L, prior.mean)]), rcond=None
    )[0]
    g0 = J[0].T @ (J[0] @ mean0 - y[0])
    at_mean = expected_error((J[0].T @ J[0])[None], g0[None], mean0[None, 1:], prior)[0]
    np.testing.assert_allclose(
        at_mean, np.linalg.inv(np.vstack([J[0], W]).T @ np.vstack([J[0], W])), rtol=1e-8
    )


def test_reflectance_prior_is_the_training_weights_and_what_the_basis_misses():
    basis = default_basis()
    prior = reflectance_prior(basis)
    weights = basis.project(training_reflectances(basis.grid))
    np.testing.assert_allclose(prior.mean, weights.mean(axis=0))
    np.testing.assert_allclose(prior.cov, np.cov(weights, rowvar=False))
    # 8 components leave about 0.01 RMS per band outside the span; all 31 leave nothing
    assert 0.003 < float(np.sqrt(np.mean(prior.truncation_var))) < 0.03
    full = pca_basis(training_reflectances(basis.grid), 31)
    assert np.max(reflectance_prior(full).truncation_var) < 1e-20


def test_reflectance_std_covers_the_actual_error_and_ranks_it():
    # the regularisers decide what 2 illuminations cannot see: the std must hold that error
    # (~95 % of the truths inside ±2σ) and be largest where it is (the plain Gauss–Newton std,
    # with the regularisers as its prior, ranks it far worse)
    # (without the upper bound: on this scene the bounds cut exactly the smoothness
    # overshoots the std's offset term ranks, and the rest of the error sits where few views
    # see a vertex, which the std ranks less well — bench/README.md)
    scene = make_scene(3, 12, noise=0.003, seed=0)
    cfg = OptimiseSettings(outer_iterations=1, joint_iterations=5, light_iterations=5)
    result = optimise(replace(scene.input(), reflectance_upper=np.inf), cfg)
    unc = result.uncertainty
    assert unc is not None and unc.reflectance_std_gn is not None
    seen = result.observed
    err = result.reflectance[seen] - scene.reflectance[seen]
    rms = np.sqrt(np.mean(err**2, axis=1))
    std = unc.reflectance_std[seen]
    assert 0.85 <= np.mean(np.abs(err) <= 2 * std) <= 0.99
    rank = spearmanr(std.mean(axis=1), rms).statistic
    assert rank >= 0.5
    gn = unc.reflectance_std_gn[seen]
    assert spearmanr(gn.mean(axis=1), rms).statistic < rank - 0.25
