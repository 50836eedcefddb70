"""Coarse to fine: blurred image levels let a start several pixels off converge."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from core.errors import RigError
from reconstruct.optimise.problem import Frames
from reconstruct.optimise.sampling import bilinear, blur_frames
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.steps import coarse_blurs, optimise
from reconstruct.optimise.synthetic import make_scene, perturb
from reconstruct.outputs.evaluate import surface_distance


def test_blur_reaches_sigma_and_keeps_saturation_out() -> None:
    images = np.zeros((2, 40, 60, 3), dtype=np.float32)
    images[:, :, 30:] = 0.5  # a vertical edge at u = 30
    images[:, 5:10, 5:10] = 9.0  # a saturated block, masked out
    valid = np.ones(images.shape[:3], dtype=bool)
    valid[:, 5:10, 5:10] = False
    frames = Frames(np.array([0, 1]), np.array([0, 0]), images, valid)
    out = blur_frames(frames, np.array([1.0, 4.0]))
    assert out.images is not None and out.valid is not None
    uv = np.array([[24.0, 20.0], [24.0, 20.0]])  # 6 px left of the edge
    _, grad = bilinear(out.images, np.array([0, 1]), uv)
    assert abs(grad[0, 0, 0]) < 1e-4 < grad[1, 0, 0]  # only the σ = 4 view sees the edge
    assert np.all(out.images[:, :12, :12] < 1e-6)  # the saturated block did not bleed
    # a small block is filled in from its valid neighbours once σ is larger than it
    assert not out.valid[0, 7, 7] and out.valid[1, 7, 7] and out.valid[:, 20, 20].all()
    assert frames.images is images  # the input is not modified


def test_float16_frames_blur_as_float32_ones_and_stay_float16() -> None:
    """The pipeline keeps frames as float16; ndimage cannot filter that, so the blur works in
    float32 and stores float16 — equal to the float32 blur up to float16 rounding."""
    rng = np.random.default_rng(0)
    images = rng.uniform(0.0, 1.0, (2, 30, 40, 3)).astype(np.float16)
    valid = rng.uniform(size=images.shape[:3]) > 0.05
    frames = Frames(np.array([0, 1]), np.array([0, 0]), images, valid)
    half = blur_frames(frames, np.array([1.5, 3.0]))
    full = blur_frames(
        Frames(frames.view, frames.illumination, images.astype(np.float32), valid),
        np.array([1.5, 3.0]),
    )
    assert half.images is not None and full.images is not None
    assert half.images.dtype == np.float16
    assert np.array_equal(half.valid, full.valid)
    assert np.allclose(half.images, full.images, rtol=1e-3, atol=1e-4)


def test_coarse_settings_are_checked() -> None:
    cfg = OptimiseSettings.from_mapping({"coarse_blur_px": 4, "coarse_levels": 3})
    assert coarse_blurs(cfg, images=True) == [4.0, 2.0, 1.0]
    assert coarse_blurs(cfg, images=False) == []  # fixed observations: nothing to blur
    assert coarse_blurs(OptimiseSettings(), images=True) == []
    with pytest.raises(RigError, match="coarse_blur_px"):
        OptimiseSettings.from_mapping({"coarse_blur_px": -1.0})
    with pytest.raises(RigError, match="coarse_levels"):
        OptimiseSettings.from_mapping({"coarse_levels": 1.5})


def test_start_several_pixels_off_converges_only_coarse_to_fine() -> None:
    # 24 Voronoi patches like the external-renderer scenes; 1 px ≈ 0.8 mm at the object, the
    # start is displaced by 5 mm RMS along the normals (≈ 6 px), the light starts at v = 0.
    scene = make_scene(subdivisions=3, n_views=8, image_size=(200, 150), voronoi=24)
    start = perturb(scene, 0.005)
    truth = trimesh.Trimesh(scene.vertices, scene.faces, process=False)
    before = np.mean(surface_distance(start, truth)[0])
    # plain least squares: the disparity cue's reach, not the loss, is what is measured
    common = {"outer_iterations": 2, "light_iterations": 10, "joint_iterations": 10}
    common["robust"] = "none"
    after = {}
    for blur in (0.0, 4.0):
        cfg = OptimiseSettings(**common, coarse_blur_px=blur)  # type: ignore[arg-type]
        res = optimise(scene.input(start, images=True), cfg)
        after[blur] = np.mean(surface_distance(res.vertices, truth)[0])
        stages = [h["stage"] for h in res.history if h["iteration"] == 0]
        assert stages == ["light"] + ["coarse"] * (2 if blur else 0) + ["joint"] * 2 + ["colour"]
    assert after[0.0] > 0.6 * before  # stuck
    assert after[4.0] < 0.5 * before
    assert after[4.0] < 0.7 * after[0.0]
