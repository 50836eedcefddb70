"""Optimisation checkpoints: an interrupted solve resumes after its last completed stage and
ends where an uninterrupted one does; other inputs or settings start afresh."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from reconstruct.optimise.checkpoint import Checkpoint, input_key
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.steps import optimise
from reconstruct.optimise.synthetic import SyntheticScene

CFG = OptimiseSettings(outer_iterations=2, light_iterations=4, joint_iterations=3)


class Stop(KeyboardInterrupt):
    """Raised from the progress callback: an interruption inside a stage."""


def stop_in(stage: str):  # type: ignore[no-untyped-def]
    def progress(name: str, rec: object) -> None:
        if name == stage:
            raise Stop

    return progress


@pytest.mark.parametrize(
    ("interrupt_in", "gloss"),
    [("joint 1", "none"), ("joint 2", "none"), ("joint 2", "fit"), ("colour 3", "fit")],
)
def test_resume_after_an_interruption_equals_an_uninterrupted_run(
    tmp_path: Path, scene: SyntheticScene, interrupt_in: str, gloss: str
) -> None:
    """``gloss: fit`` ends with a colour stage (3 here), which a resume must not skip."""
    cfg = replace(CFG, gloss=gloss)
    inp = scene.input(scene.vertices + 0.0005, images=False)
    reference = optimise(inp, cfg)
    checkpoint = Checkpoint(tmp_path / "checkpoint.npz", input_key(inp, cfg))
    with pytest.raises(Stop):
        optimise(inp, cfg, stop_in(interrupt_in), checkpoint)
    saved = checkpoint.load()
    assert saved is not None and not saved.done
    assert saved.stage == int(interrupt_in.split()[1]) - 1  # the last completed stage
    seen: list[str] = []
    resumed = optimise(inp, cfg, lambda name, rec: seen.append(name), checkpoint)
    assert "light 0" not in seen  # the completed stages were not run again
    np.testing.assert_array_equal(resumed.vertices, reference.vertices)
    np.testing.assert_array_equal(resumed.alpha, reference.alpha)
    np.testing.assert_array_equal(resumed.light, reference.light)
    np.testing.assert_array_equal(resumed.observed, reference.observed)
    assert len(resumed.history) == len(reference.history)
    # A finished checkpoint returns the result without solving again.
    again: list[str] = []
    final = optimise(inp, cfg, lambda name, rec: again.append(name), checkpoint)
    assert again == []
    np.testing.assert_array_equal(final.vertices, reference.vertices)


def test_a_checkpoint_for_other_settings_is_ignored(tmp_path: Path, scene: SyntheticScene) -> None:
    inp = scene.input(scene.vertices, images=False)
    path = tmp_path / "checkpoint.npz"
    short = OptimiseSettings(outer_iterations=1, light_iterations=2, joint_iterations=1)
    optimise(inp, short, None, Checkpoint(path, input_key(inp, short)))
    assert Checkpoint(path, input_key(inp, short)).load() is not None
    assert input_key(inp, CFG) != input_key(inp, short)
    assert Checkpoint(path, input_key(inp, CFG)).load() is None
    seen: list[str] = []
    optimise(inp, CFG, lambda name, rec: seen.append(name), Checkpoint(path, input_key(inp, CFG)))
    assert seen[0] == "light 0"


def test_an_unreadable_checkpoint_starts_afresh(tmp_path: Path, scene: SyntheticScene) -> None:
    inp = scene.input(scene.vertices, images=False)
    path = tmp_path / "checkpoint.npz"
    path.write_bytes(b"PK\x03\x04 torn")
    assert Checkpoint(path, input_key(inp, CFG)).load() is None


def test_the_key_covers_the_frames_noise_weights(scene: SyntheticScene) -> None:
    """Ambient subtraction weights each frame; other weights are another problem."""
    inp = scene.input(scene.vertices, images=True)
    key = input_key(inp, CFG)
    weighted = replace(inp.frames, weight=np.full(inp.frames.view.size, 0.5))
    assert input_key(replace(inp, frames=weighted), CFG) != key
    assert input_key(inp, CFG) == key  # the shared scene is left as it was


@pytest.mark.parametrize("interrupt_in", ["coarse 2", "joint 3"])
def test_coarse_to_fine_resumes_at_its_level(
    tmp_path: Path, image_scene: SyntheticScene, interrupt_in: str
) -> None:
    cfg = OptimiseSettings(
        outer_iterations=1, light_iterations=2, joint_iterations=2, coarse_blur_px=3.0
    )
    inp = image_scene.input(image_scene.vertices + 0.0005, images=True)
    reference = optimise(inp, cfg)
    checkpoint = Checkpoint(tmp_path / "checkpoint.npz", input_key(inp, cfg))
    with pytest.raises(Stop):
        optimise(inp, cfg, stop_in(interrupt_in), checkpoint)
    seen: list[str] = []
    resumed = optimise(inp, cfg, lambda name, rec: seen.append(name), checkpoint)
    assert seen[0] == interrupt_in  # resumed at the interrupted stage, on its level's images
    np.testing.assert_array_equal(resumed.vertices, reference.vertices)
    np.testing.assert_array_equal(resumed.light, reference.light)
