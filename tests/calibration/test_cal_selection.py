"""Illumination selection: the expected-error formula and the ranking."""

from __future__ import annotations

import numpy as np
import pytest

from calibration import defaults
from calibration.basis import SpectralBasis, default_basis
from calibration.estimation import estimate_reflectance
from calibration.selection import (
    channel_mixtures,
    expected_rmse,
    normalised_responses,
    rank_illumination_sets,
)
from core.errors import RigError

Setup = tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, SpectralBasis]


@pytest.fixture(scope="module")
def setup() -> Setup:
    ch = defaults.rgbcw_channel_spds()
    lights = {
        k: defaults.illumination_spd(v, ch) for k, v in defaults.default_illuminations().items()
    }
    return (
        lights,
        defaults.camera_sensitivity(),
        defaults.colorchecker_reflectances()[1],
        default_basis(),
    )


def test_expected_rmse_matches_monte_carlo(setup: Setup) -> None:
    lights, camera, refl, basis = setup
    resp = normalised_responses(camera, [lights["LED1"], lights["LED2"]])
    noise = 0.01
    predicted = expected_rmse(resp, refl, basis, noise, smoothness=0.1)
    rng = np.random.default_rng(7)
    clean = np.einsum("knl,pl->pkn", resp, refl)
    trials = 2000
    noisy = clean[None] + noise * rng.standard_normal((trials, *clean.shape))
    # the linear estimator the model describes: smoothness, no bounds
    _, est = estimate_reflectance(
        noisy.reshape(-1, 2, 3), resp, basis, 0.1, bounds=None, regulariser="smoothness"
    )
    mse = np.mean((est.reshape(trials, 24, 31) - refl[None]) ** 2, axis=(0, 2))
    assert np.mean(predicted**2) == pytest.approx(np.mean(mse), rel=0.02)
    np.testing.assert_allclose(predicted, np.sqrt(mse), rtol=0.04)


def test_noise_free_ranking_prefers_more_illuminations(setup: Setup) -> None:
    lights, camera, refl, basis = setup
    scores = rank_illumination_sets(lights, camera, refl, basis, max_size=3, noise=0.0)
    assert len(scores) == 7
    assert [s.mean_rmse for s in scores] == sorted(s.mean_rmse for s in scores)
    by_name = {s.names: s.mean_rmse for s in scores}
    # as in the paper: two or three illuminations beat any single one
    assert max(by_name[("LED1", "LED2")], by_name[("LED1", "LED2", "LED3")]) < min(
        by_name[(n,)] for n in lights
    )


def test_reflectances_in_span_with_full_rank_are_exact(setup: Setup) -> None:
    lights, camera, _, basis = setup
    rng = np.random.default_rng(8)
    refl = basis.reconstruct(rng.standard_normal((10, 8)) * 0.05 + np.r_[2.0, np.zeros(7)])
    scores = rank_illumination_sets(lights, camera, refl, basis, noise=0.0, smoothness=0.0)
    best = scores[0]
    assert best.names == ("LED1", "LED2", "LED3") and best.mean_rmse < 1e-5


def test_mixtures_and_limits(setup: Setup) -> None:
    lights, camera, refl, basis = setup
    mixes = channel_mixtures(defaults.rgbcw_channel_spds())
    assert len(mixes) == 31 and "r+g+b" in mixes
    np.testing.assert_allclose(
        mixes["r+c"], defaults.rgbcw_channel_spds()["r"] + defaults.rgbcw_channel_spds()["c"]
    )
    assert len(channel_mixtures({"a": np.ones(3), "b": np.ones(3)}, (0.0, 0.5, 1.0))) == 8
    with pytest.raises(RigError, match="subsets"):
        rank_illumination_sets(mixes, camera, refl, basis, max_size=6)
    with pytest.raises(RigError, match="no candidate"):
        rank_illumination_sets({}, camera, refl, basis)
    with pytest.raises(RigError, match="no camera signal"):
        rank_illumination_sets({"off": np.zeros(31)}, camera, refl, basis)
    with pytest.raises(RigError, match="smoothness -1 is negative"):
        rank_illumination_sets(lights, camera, refl, basis, smoothness=-1.0)
