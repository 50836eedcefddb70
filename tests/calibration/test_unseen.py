"""What the responses barely see is the spectral regulariser's (calibration/unseen.py)."""

from __future__ import annotations

import numpy as np

from calibration.basis import default_basis
from calibration.bounds import ROUND_OFF
from calibration.defaults import training_reflectances
from calibration.estimation import stacked_responses
from calibration.prior import smoothness_gram
from calibration.unseen import complete_unseen, weak_directions
from reconstruct.optimise.synthetic import default_responses

BASIS = default_basis()
B = BASIS.B
P = smoothness_gram(B)


def test_weak_directions_are_those_seen_below_the_share() -> None:
    two, three = default_responses(("LED1", "LED2")), default_responses(("LED1", "LED2", "LED3"))
    # six numbers for eight weights: at least two directions unseen, whatever the share
    assert weak_directions(B, two, 1e-9).shape == (8, 2)
    assert weak_directions(B, three, 0.0).shape == (8, 0)
    weak = weak_directions(B, three, 0.003)
    assert weak.shape == (8, 1)  # the built-in bulb's three settings see the eighth barely
    assert np.allclose(weak.T @ weak, np.eye(1))
    rows = stacked_responses(three, B)
    strongest = np.linalg.norm(rows, ord=2)
    assert np.linalg.norm(rows @ weak) < 0.003 * strongest


def test_the_unseen_part_is_the_regularisers_minimum_and_the_colours_stay() -> None:
    responses = default_responses(("LED1", "LED2"))
    weak = weak_directions(B, responses, 0.003)
    truth = BASIS.project(training_reflectances()[:20])
    rough = truth + 0.15 * np.sin(np.arange(20))[:, None] * weak[:, 0]
    done = complete_unseen(rough, B, responses, P, 0.003)
    rows = stacked_responses(responses, B)
    assert np.allclose(done @ rows.T, rough @ rows.T, atol=1e-9)
    for a, d in zip(rough, done, strict=True):
        r = B @ d
        if r.min() > 1e-9 and r.max() < 1 - 1e-9:  # inside the bounds: no move along them helps
            assert np.allclose(weak.T @ P @ d, 0.0, atol=1e-9 * np.trace(P))
        assert d @ P @ d <= a @ P @ a + 1e-12


def test_a_barely_seen_direction_follows_the_regulariser_not_the_noise() -> None:
    # Three illuminations: a per-vertex least-squares fit with 1 % noise puts noise, amplified
    # by the eighth direction's small singular value, into the spectrum; the completion takes
    # it out and leaves the colours as fitted.
    rng = np.random.default_rng(1)
    responses = default_responses(("LED1", "LED2", "LED3"))
    rows = stacked_responses(responses, B)
    truth = training_reflectances()[rng.choice(214, 200, replace=False)]
    rgb = BASIS.project(truth) @ rows.T
    noisy = rgb * (1 + 0.01 * rng.standard_normal(rgb.shape))
    fitted = np.linalg.lstsq(rows, noisy.T, rcond=None)[0].T
    done = complete_unseen(fitted, B, responses, P, 0.003, -np.inf, np.inf)
    error = [np.sqrt(np.mean((a @ B.T - truth) ** 2)) for a in (fitted, done)]
    assert error[1] < 0.5 * error[0]
    moved = np.linalg.norm(done @ rows.T - fitted @ rows.T)
    assert moved < 0.25 * np.linalg.norm(noisy - rgb)  # a fraction of the noise it removes


def test_the_completion_stays_within_the_bounds() -> None:
    responses = default_responses(("LED1", "LED2"))
    dark = BASIS.project(0.05 * training_reflectances())  # valid, near the lower bound
    dark = dark[(dark @ B.T).min(axis=1) >= 0]
    free = complete_unseen(dark, B, responses, P, 0.003, -np.inf, np.inf)
    dips = (free @ B.T).min(axis=1) < -1e-3  # the smoothest spectrum with these colours
    assert dips.sum() >= 5
    done = complete_unseen(dark, B, responses, P, 0.003)
    r = done @ B.T
    assert r.min() >= -ROUND_OFF and r.max() <= 1 + ROUND_OFF
    rows = stacked_responses(responses, B)
    assert np.allclose(done @ rows.T, dark @ rows.T, rtol=1e-4, atol=1e-9)
    inside = (free @ B.T).min(axis=1) >= -ROUND_OFF
    assert np.array_equal(done[inside], free[inside])  # rows the bounds leave free: exact


def test_share_zero_changes_nothing() -> None:
    responses = default_responses(("LED1", "LED2", "LED3"))
    alpha = BASIS.project(training_reflectances()[:5])
    assert np.array_equal(complete_unseen(alpha, B, responses, P, 0.0), alpha)


def test_the_modules_examples_hold() -> None:
    import doctest

    import calibration.unseen

    assert doctest.testmod(calibration.unseen).failed == 0
