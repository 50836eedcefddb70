"""``optimise.gloss: fit``: a neutral GGX lobe fitted to the diffuse model's residual and its
highlight taken off the observations before each joint stage, and before the colour stage
where it is the gloss."""

from __future__ import annotations

import numpy as np
import pytest

from reconstruct.optimise.gloss import ROUGHNESS, colour_without_gloss, fit_gloss
from reconstruct.optimise.problem import Problem
from reconstruct.optimise.problem_setup import build_problem
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.steps import optimise
from reconstruct.optimise.synthetic import SyntheticScene, with_gloss


@pytest.fixture(scope="module")
def glossy(scene: SyntheticScene) -> SyntheticScene:
    return with_gloss(scene, 0.04, 0.2)


def problem_at_truth(scene: SyntheticScene) -> tuple[Problem, np.ndarray]:
    light = scene.light_offset[None]
    problem = build_problem(scene.input(), scene.vertices, light, OptimiseSettings())
    return problem, problem.pack(scene.vertices, scene.alpha, light)


def fit_at_truth(scene: SyntheticScene) -> tuple[float, float, float]:
    fit = fit_gloss(*problem_at_truth(scene))
    return fit.specular, fit.roughness, fit.explained


def test_the_lobe_of_a_glossy_scene_is_found_and_a_matte_one_has_none(
    scene: SyntheticScene, glossy: SyntheticScene
) -> None:
    specular, roughness, explained = fit_at_truth(glossy)
    assert roughness == 0.2 and specular == pytest.approx(0.04, rel=0.15)
    assert explained > 0.8  # at the true diffuse colours the residual is the highlight
    specular, _, explained = fit_at_truth(scene)
    assert specular < 0.004 and explained < 0.05


def test_the_colour_stage_takes_off_a_lobe_that_is_gloss_and_leaves_a_matte_scene_as_it_is(
    scene: SyntheticScene, glossy: SyntheticScene
) -> None:
    problem, theta = problem_at_truth(glossy)
    without, fit = colour_without_gloss(problem, theta)
    assert fit is not None and fit.roughness == 0.2
    np.testing.assert_array_equal(without.weights.observed_offset, fit.highlight)
    problem, theta = problem_at_truth(scene)
    assert colour_without_gloss(problem, theta) == (problem, None)


def test_the_colour_of_a_glossy_scene_is_not_brightened_by_its_gloss(
    scene: SyntheticScene, glossy: SyntheticScene
) -> None:
    """Left in the colour stage, the lobe's tails raise every reflectance against the same
    solve of the matte scene (by more than the bound here); taken off, they do not."""

    def mean_error(observed: SyntheticScene) -> float:
        cfg = OptimiseSettings(outer_iterations=2, joint_iterations=6, highlights=True, gloss="fit")
        res = optimise(observed.input(), cfg)
        return float(np.mean((res.reflectance - scene.reflectance)[res.observed]))

    assert abs(mean_error(glossy) - mean_error(scene)) < 0.0025


def errors(scene: SyntheticScene, truth: SyntheticScene, **settings: object) -> tuple[float, float]:
    cfg = OptimiseSettings(outer_iterations=2, joint_iterations=6, **settings)  # type: ignore[arg-type]
    res = optimise(scene.input(), cfg)
    light = float(np.linalg.norm(res.light[0] - truth.light_offset))
    rmse = float(np.sqrt(np.mean((res.reflectance - truth.reflectance)[res.observed] ** 2)))
    return light, rmse


def test_the_solve_on_a_glossy_scene_is_better_with_the_lobe_taken_off(
    scene: SyntheticScene, glossy: SyntheticScene
) -> None:
    light_none, rmse_none = errors(glossy, scene)
    light_fit, rmse_fit = errors(glossy, scene, gloss="fit")
    assert rmse_fit < 0.8 * rmse_none and light_fit < 0.8 * light_none
    # with the highlights down-weighted first, the light stage is not pulled off to begin with
    light_down, rmse_down = errors(glossy, scene, highlights=True)
    light_both, rmse_both = errors(glossy, scene, highlights=True, gloss="fit")
    assert rmse_both < 0.9 * rmse_down and light_both < 0.5 * light_down


def test_a_matte_scene_is_left_as_it_was(scene: SyntheticScene) -> None:
    light_none, rmse_none = errors(scene, scene)
    light_fit, rmse_fit = errors(scene, scene, gloss="fit")
    assert abs(light_fit - light_none) < 1e-3 and rmse_fit < 1.02 * rmse_none


def test_each_stage_reports_the_lobe_it_took_off(glossy: SyntheticScene) -> None:
    cfg = OptimiseSettings(gloss="fit", outer_iterations=1, joint_iterations=2, light_iterations=3)
    res = optimise(glossy.input(), cfg)
    fits = [h["gloss"] for h in res.history if "gloss" in h]
    assert [h["stage"] for h in res.history if "gloss" in h] == ["light", "joint", "colour"]
    assert all(f["roughness"] in ROUGHNESS and f["specular"] > 0.01 for f in fits)
