"""Highlights: a neutral excess in the lamps' own colour is found and down-weighted, a
Lambertian observation (shading errors in the surface's colour included) keeps its weight, and
the solve on a glossy synthetic scene recovers the light and reflectance better with it."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.defaults import training_reflectances
from reconstruct.optimise.highlights import group_median, highlight_weights
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.steps import optimise
from reconstruct.optimise.synthetic import SyntheticScene, default_responses, with_gloss

RESPONSES = default_responses(("LED1", "LED2"))  # (2, 3, N_λ)
WHITE = RESPONSES.sum(axis=2)
LOBE = np.radians(25.0)


def weights(
    pair: np.ndarray,
    vertex: np.ndarray,
    ill: np.ndarray,
    observed: np.ndarray,
    shading: np.ndarray,
    n: int,
    angle_deg: float = 0.0,
) -> np.ndarray:
    """The weights at the mirror direction (or ``angle_deg`` from it), tolerance 0.1."""
    angle = np.full(pair.size, np.radians(angle_deg))
    return highlight_weights(pair, vertex, ill, observed, shading, WHITE, n, 0.1, angle, LOBE)


def observations(
    reflectance: np.ndarray, views: int = 8, noise: float = 1e-4, seed: int = 0
) -> tuple[np.ndarray, ...]:
    """One vertex of each reflectance (V, N_λ) seen from ``views`` views under both lamps:
    (pair, vertex, illumination, observed, shading), sorted by (vertex, view, lamp)."""
    rng = np.random.default_rng(seed)
    n = len(reflectance)
    vertex = np.repeat(np.arange(n), 2 * views)
    view = np.tile(np.repeat(np.arange(views), 2), n)
    illumination = np.tile([0, 1], n * views)
    shading = np.repeat(rng.uniform(4.0, 12.0, n * views), 2)  # cos θ / d² at 0.3–0.5 m
    colour = np.einsum("vl,kcl->vkc", reflectance, RESPONSES)
    observed = shading[:, None] * colour[vertex, illumination]
    observed += noise * rng.normal(size=observed.shape)
    return vertex * views + view, vertex, illumination, observed, shading


def test_group_median_matches_numpy() -> None:
    rng = np.random.default_rng(1)
    group = rng.integers(0, 6, 200)
    values = rng.normal(size=(200, 3))
    out = group_median(group, values, 7)
    for g in range(6):
        assert np.allclose(out[g], np.median(values[group == g], axis=0))
    assert np.all(np.isnan(out[6]))


def test_a_neutral_excess_is_down_weighted_and_a_lambertian_one_is_not() -> None:
    refl = training_reflectances()[[10, 60, 120, 180]]  # coloured surfaces
    pair, vertex, ill, observed, shading = observations(refl)
    glossy = (pair == 3) | (pair == 12)  # one view of vertex 0 and one of vertex 1
    observed[glossy] += 0.15 * shading[glossy, None] * WHITE[ill[glossy]]  # highlight, h = 0.15
    brighter = pair == 20  # a shading 30 % too low: an excess in the surface's own colour
    observed[brighter] *= 1.3
    w = weights(pair, vertex, ill, observed, shading, len(refl))
    assert np.all(w[glossy] < 0.05)
    assert np.all(w[brighter] > 0.95)
    assert np.all(w[~glossy] > 0.9)


def test_on_a_grey_surface_only_a_difference_beyond_the_tolerance_counts() -> None:
    """Grey: a shading error is neutral too, so a large one counts on both sides (no bias)."""
    grey = np.full((2, RESPONSES.shape[2]), 0.4)
    pair, vertex, ill, observed, shading = observations(grey)
    small, large, deficit = pair == 2, pair == 10, pair == 12
    observed[small] *= 1.04  # a shading error (or a faint lobe) within the tolerance
    observed[large] += 0.3 * shading[large, None] * WHITE[ill[large]]  # 75 % of the diffuse
    observed[deficit] *= 0.5
    w = weights(pair, vertex, ill, observed, shading, 2)
    assert np.all(w[small] > 0.95)
    assert np.all(w[large] < 0.01)
    assert np.all(w[deficit] < 0.05)
    assert np.all(w[~(large | deficit)] > 0.95)


def test_far_from_the_mirror_direction_an_excess_is_left_to_the_shading() -> None:
    refl = training_reflectances()[[10, 60]]
    pair, vertex, ill, observed, shading = observations(refl)
    glossy = pair == 3
    observed[glossy] += 0.03 * shading[glossy, None] * WHITE[ill[glossy]]
    assert np.all(weights(pair, vertex, ill, observed, shading, 2, 0.0)[glossy] < 0.1)
    assert np.all(weights(pair, vertex, ill, observed, shading, 2, 60.0)[glossy] > 0.9)


def test_a_dark_surface_is_judged_against_the_noise() -> None:
    """A noisy dark vertex: its own relative scatter is far above the tolerance, yet its
    observations keep their weight; a highlight many noise spreads high does not."""
    refl = np.vstack([training_reflectances()[[10, 60, 120]], np.full(31, 0.01)])
    pair, vertex, ill, observed, shading = observations(refl, views=12, noise=0.002, seed=4)
    glossy = pair == 40  # a view of the dark vertex (index 3)
    observed[glossy] += 0.1 * shading[glossy, None] * WHITE[ill[glossy]]
    w = weights(pair, vertex, ill, observed, shading, 4)
    dark = (vertex == 3) & ~glossy
    assert np.mean(w[dark] > 0.9) > 0.9
    assert np.all(w[glossy] < 0.05)


def light_and_reflectance_error(
    scene: SyntheticScene, truth: SyntheticScene, on: bool
) -> tuple[float, float]:
    cfg = OptimiseSettings(highlights=on, optimise_positions=False, light_iterations=15)
    res = optimise(scene.input(), cfg)
    light = float(np.linalg.norm(res.light[0] - truth.light_offset))
    rmse = float(np.sqrt(np.mean((res.reflectance - truth.reflectance)[res.observed] ** 2)))
    return light, rmse


@pytest.fixture(scope="module")
def glossy(scene: SyntheticScene) -> SyntheticScene:
    return with_gloss(scene, 0.04, 0.2)


def test_the_solve_on_a_glossy_scene_is_better_with_highlights_down_weighted(
    scene: SyntheticScene, glossy: SyntheticScene
) -> None:
    light_off, rmse_off = light_and_reflectance_error(glossy, scene, on=False)
    light_on, rmse_on = light_and_reflectance_error(glossy, scene, on=True)
    assert light_on < 0.5 * light_off
    assert rmse_on < 0.75 * rmse_off


def test_down_weighting_leaves_a_lambertian_scene_as_it_was(scene: SyntheticScene) -> None:
    light_off, rmse_off = light_and_reflectance_error(scene, scene, on=False)
    light_on, rmse_on = light_and_reflectance_error(scene, scene, on=True)
    assert abs(light_on - light_off) < 1e-3
    assert rmse_on < 1.01 * rmse_off
