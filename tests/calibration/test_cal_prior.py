"""The spectral regularisers: the training reflectances' prior and the paper's smoothness."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bench.external import SCENES
from bench.external_scene import camera_ssf, lamp_spd
from bench.spectral_prior import munsell
from calibration import defaults
from calibration.basis import SpectralBasis
from calibration.colour_difference import delta_e00, illuminant
from calibration.estimation import estimate_reflectance, response_matrices
from calibration.prior import (
    smoothness_gram,
    spectral_regulariser,
    weight_statistics,
)
from core.errors import RigError


def test_training_prior_is_the_rawtoaces_shape_prior(basis: SpectralBasis) -> None:
    reg = spectral_regulariser("training", basis)
    raw = defaults.rawtoaces_reflectances()
    assert len(raw) == 190  # the ColorChecker the benchmark paints with is not in it
    stats = weight_statistics(basis, raw)
    # blind to brightness: the mean spectrum at any level costs nothing …
    assert abs(stats.mean @ reg.matrix @ stats.mean) < 1e-12 * np.trace(reg.matrix)
    # … and any other spectrum costs its Gaussian distance from the nearest brightness of μ
    # (one common scale for all)
    precision = np.linalg.inv(stats.cov)
    x = np.random.default_rng(1).standard_normal((20, 8))
    c = (x @ precision @ stats.mean) / (stats.mean @ precision @ stats.mean)
    d = x - c[:, None] * stats.mean
    ratio = np.einsum("pi,ij,pj->p", x, reg.matrix, x) / np.einsum("pi,ij,pj->p", d, precision, d)
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-8)
    assert np.linalg.matrix_rank(reg.matrix, tol=1e-9 * np.trace(reg.matrix)) == 7
    np.testing.assert_allclose(reg.factor.T @ reg.factor, reg.matrix, atol=1e-12)


def test_smoothness_is_the_papers_term(basis: SpectralBasis) -> None:
    reg = spectral_regulariser("smoothness", basis)
    np.testing.assert_allclose(reg.matrix, smoothness_gram(basis.B))


def test_an_unknown_regulariser_names_the_choices(basis: SpectralBasis) -> None:
    with pytest.raises(RigError, match="training, smoothness"):
        spectral_regulariser("flat", basis)  # type: ignore[arg-type]


def test_the_prior_treats_an_unknown_scale_alike(
    basis: SpectralBasis, responses: np.ndarray
) -> None:
    _, refl = defaults.colorchecker_reflectances()
    rgb = np.einsum("knl,pl->pkn", responses, refl)
    one, seven = (
        estimate_reflectance(y, responses, basis, fit_scale=True, regulariser="training")[1]
        for y in (rgb, 7.0 * rgb)
    )
    np.testing.assert_allclose(one, seven, atol=1e-9)


def test_training_prior_beats_smoothness_on_chips_it_never_saw(
    basis: SpectralBasis, shared_data: Path
) -> None:
    # 1269 Munsell chips (in neither the basis' nor the prior's training set) through each
    # measured camera and lamp pair of the external benchmark, 1 % noise
    chips = munsell(shared_data)
    d65 = illuminant("D65")
    for spec in SCENES.values():
        lamps = [lamp_spd(shared_data, name) for name in spec.lamps.values()]
        resp = response_matrices(camera_ssf(shared_data, spec.camera), lamps)
        rgb = np.einsum("knl,pl->pkn", resp, chips)
        rgb *= 1 + 0.01 * np.random.default_rng(0).standard_normal(rgb.shape)
        errors = {
            name: delta_e00(estimate_reflectance(rgb, resp, basis, regulariser=name)[1], chips, d65)
            for name in ("training", "smoothness")
        }
        assert errors["training"].mean() < 0.9 * errors["smoothness"].mean(), spec.name
