"""Light handling for projector sessions: fixed lights, free lights from the front's start."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, cast

import numpy as np
import pytest

from core.errors import RigError
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.steps import optimise
from reconstruct.optimise.synthetic import SyntheticScene
from reconstruct.run.front import FrontResult
from reconstruct.run.pipeline import FRONT_SECTIONS, projector_lights

FAST: dict[str, Any] = {"outer_iterations": 1, "light_iterations": 3, "joint_iterations": 3}


def true_positions(scene: SyntheticScene) -> np.ndarray:
    return np.stack([p.light_position(scene.light_offset) for p in scene.rig.poses])


def test_fixed_lights_keep_their_positions_exactly(scene: SyntheticScene) -> None:
    inp = scene.input()
    start = true_positions(scene) + 0.003
    inp.initial_light = start
    res = optimise(inp, OptimiseSettings(light_mode="fixed", **FAST))
    assert np.array_equal(res.light_positions, start)
    assert {h["stage"] for h in res.history} == {"light", "joint"}


def test_fixed_lights_without_positions_are_an_error(scene: SyntheticScene) -> None:
    with pytest.raises(RigError, match="fixed"):
        optimise(scene.input(), OptimiseSettings(light_mode="fixed", **FAST))


def test_free_lights_start_from_the_given_positions(scene: SyntheticScene) -> None:
    truth = true_positions(scene)
    inp = scene.input()
    inp.initial_light = truth + 0.002
    cfg = OptimiseSettings(light_mode="free", optimise_positions=False, light_iterations=5)
    res = optimise(inp, cfg)
    # Started 3.5 mm off, it stays near the truth; from the camera centres it would be ~6 cm off.
    assert np.max(np.linalg.norm(res.light_positions - truth, axis=1)) < 0.0035
    assert not np.array_equal(res.light_positions, inp.initial_light)


def _front(hint: str | None, positions: np.ndarray | None) -> FrontResult:
    ns: Any = SimpleNamespace(light_mode_hint=hint, initial_light_positions=positions)
    return cast(FrontResult, ns)


def test_projector_sessions_default_to_fixed_lights_from_the_front() -> None:
    pos = np.arange(6.0).reshape(2, 3)
    cfg = OptimiseSettings()
    got = projector_lights(_front("free", pos), cfg, False)
    assert got is not None and np.array_equal(got, pos)
    assert cfg.light_mode == "fixed"
    free = OptimiseSettings.from_mapping({"light_mode": "free"})
    got = projector_lights(_front("free", pos), free, True)
    assert got is not None and np.array_equal(got, pos)
    assert free.light_mode == "free"
    bulb = OptimiseSettings()
    assert projector_lights(_front(None, None), bulb, False) is None
    assert bulb.light_mode == "offset"
    assert "procam" in FRONT_SECTIONS


def test_unknown_light_mode_is_rejected() -> None:
    with pytest.raises(RigError, match="light_mode"):
        OptimiseSettings.from_mapping({"light_mode": "wobbly"})
