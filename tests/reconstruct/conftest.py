"""Fixtures shared by the reconstruct tests: small synthetic optimiser scenes (built once per
session) and ``make_session`` for the front stages (helpers in front_synthetic.py)."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from front_synthetic import build_session

from reconstruct.optimise.cost import JointCost
from reconstruct.optimise.problem import Problem
from reconstruct.optimise.problem_setup import build_problem
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.synthetic import SyntheticScene, make_scene


@pytest.fixture(scope="session")
def scene() -> SyntheticScene:
    """Bumpy sphere, 642 vertices, 10 views × 2 illuminations, vertex-level observations."""
    return make_scene(subdivisions=3, n_views=10)


@pytest.fixture(scope="session")
def image_scene() -> SyntheticScene:
    """Bumpy sphere, 642 vertices, 8 views × 2 illuminations, rendered 200×150 images."""
    return make_scene(subdivisions=3, n_views=8, image_size=(200, 150))


def problem_at(
    scene: SyntheticScene, images: bool, mode: str = "offset", vertices: np.ndarray | None = None
) -> tuple[Problem, np.ndarray]:
    """A problem and a θ near the truth (perturbed α and light) for derivative checks."""
    rng = np.random.default_rng(3)
    cfg = OptimiseSettings(light_mode=mode)  # type: ignore[arg-type]
    X = scene.vertices if vertices is None else vertices
    if mode == "offset":
        light = (scene.light_offset + [0.01, -0.005, 0.02])[None]
    else:
        light = np.stack([p.light_position(scene.light_offset) for p in scene.rig.poses]) + 0.01
    problem = build_problem(scene.input(X, images=images), X, light, cfg)
    A = scene.alpha + 0.05 * rng.normal(size=scene.alpha.shape)
    return problem, problem.pack(X, A, light)


def cost_at(
    scene: SyntheticScene, images: bool, mode: str = "offset"
) -> tuple[JointCost, np.ndarray]:
    problem, theta = problem_at(scene, images, mode)
    return JointCost(problem), theta


@pytest.fixture
def make_session(tmp_path: Path) -> Callable[..., Path]:
    """``make_session(views=..., illuminations=..., known_poses=..., size=...)`` -> session."""
    return partial(build_session, tmp_path)
