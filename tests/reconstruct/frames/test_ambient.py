"""Ambient (room-light) subtraction: aligned frames, exposure scaling, saturation, the
hand-held fallback, the noise weight in the cost, and the sim's room light."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from core.errors import RigError
from drivers.sim import SimRig
from reconstruct.frames.ambient import exposure_ratio, subtract_ambient
from reconstruct.optimise.cost import JointCost
from reconstruct.optimise.problem import Frames
from reconstruct.optimise.problem_setup import build_problem
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.synthetic import SyntheticScene, make_scene


@pytest.fixture(scope="module")
def pair() -> tuple[SyntheticScene, SyntheticScene]:
    """The same noise-free scene in a dark room and with a room light at 10 % of the bulb."""
    common = {"n_views": 3, "image_size": (200, 150)}
    dark = make_scene(2, **common)  # type: ignore[arg-type]
    room = make_scene(2, ambient=0.1, **common)  # type: ignore[arg-type]
    return dark, room


def _ones(img: np.ndarray) -> np.ndarray:
    return np.ones(img.shape[:2], dtype=bool)


def test_aligned_subtraction_recovers_the_dark_frame(pair):
    dark, room = pair
    assert room.ambient_images is not None and dark.frames.images is not None
    lit, amb = room.frames.images[0], room.ambient_images[0]
    assert np.abs(lit - dark.frames.images[0]).max() > 0.005  # the room light is visible
    out = subtract_ambient(lit, _ones(lit), amb, _ones(amb), 1.0, "view 0 LED1")
    assert out.aligned and out.shift_px < 1.0
    np.testing.assert_allclose(out.image, dark.frames.images[0], atol=1e-5)
    # variances add: less weight than a dark-room frame, more than none
    assert 0.3 < out.weight < 1.0


def test_exposure_ratio_scales_the_ambient_frame(pair):
    dark, room = pair
    assert room.ambient_images is not None and dark.frames.images is not None
    lit, amb = room.frames.images[1], room.ambient_images[0]
    ratio = exposure_ratio(0.8, 400, 0.4, 400)  # ambient frame at half the shutter time
    assert ratio == pytest.approx(2.0)
    out = subtract_ambient(lit, _ones(lit), amb / 2, _ones(amb), ratio, "view 0 LED2")
    np.testing.assert_allclose(out.image, dark.frames.images[1], atol=1e-5)


def test_saturation_masks_of_both_frames_are_kept(pair):
    _, room = pair
    assert room.ambient_images is not None and room.frames.images is not None
    lit, amb = room.frames.images[0], room.ambient_images[0]
    lit_ok, amb_ok = _ones(lit), _ones(amb)
    lit_ok[10:20, 10:20] = False
    amb_ok[100:110, 50:60] = False
    out = subtract_ambient(lit, lit_ok, amb, amb_ok, 1.0, "view 0 LED1")
    assert not out.valid[15, 15] and not out.valid[105, 55]
    assert out.valid.sum() == lit_ok.size - 200


def test_moved_ambient_frame_falls_back_with_a_warning(pair, caplog):
    dark, room = pair
    assert room.ambient_images is not None and dark.frames.images is not None
    assert room.frames.images is not None
    lit = room.frames.images[0]
    moved = np.roll(room.ambient_images[0], (7, -5), axis=(0, 1))
    aligned = subtract_ambient(lit, _ones(lit), room.ambient_images[0], _ones(lit), 1.0, "v")
    with caplog.at_level(logging.WARNING, logger="reconstruct.frames.ambient"):
        out = subtract_ambient(lit, _ones(lit), moved, _ones(lit), 1.0, "view 0 LED1")
    assert not out.aligned and out.shift_px == pytest.approx(np.hypot(7, 5), abs=1.0)
    assert "view 0 LED1" in caplog.text and "px off" in caplog.text
    assert out.weight < aligned.weight
    # the per-channel level takes out most of the room light on the object
    obj = dark.frames.images[0].sum(axis=2) > 0.02
    before = np.abs(lit - dark.frames.images[0])[obj].mean()
    after = np.abs(out.image - dark.frames.images[0])[obj].mean()
    assert after < 0.5 * before


def test_frame_weight_scales_the_rendering_residuals(pair):
    dark, _ = pair
    inp = dark.input(images=True)
    light = dark.light_offset[None]
    cfg = OptimiseSettings()
    base = JointCost(build_problem(inp, dark.vertices, light, cfg))
    f = inp.frames
    weight = np.linspace(0.5, 1.0, f.count)
    inp.frames = Frames(f.view, f.illumination, f.images, f.valid, weight)
    weighted = JointCost(build_problem(inp, dark.vertices, light, cfg))
    o = weighted.p.obs
    np.testing.assert_allclose(weighted.obs_weight, base.obs_weight * weight[o.frame])


def test_sim_room_light_is_in_the_bulb_off_frame():
    conf = {"scene": "blob", "subdivisions": 3, "camera": {"width": 120, "height": 90}}
    plain = SimRig(conf)
    lit_room = SimRig({**conf, "ambient": {"level": 0.1, "spd": "FL2"}})
    for rig in (plain, lit_room):
        rig.light.off()
    assert plain.camera.render_linear().max() == 0.0
    room = lit_room.camera.render_linear()
    assert room.max() > 0.0
    plain.light.set_illumination("LED2")
    lit_room.light.set_illumination("LED2")
    # in a lit frame the room light adds exactly the bulb-off frame
    np.testing.assert_allclose(
        lit_room.camera.render_linear() - plain.camera.render_linear(), room, atol=1e-9
    )


def test_sim_room_light_config_errors_name_the_key():
    unknown = r"'sim\.ambient\.levle' is not known \(did you mean 'level'\?\)"
    with pytest.raises(RigError, match=unknown):
        SimRig({"scene": "blob", "subdivisions": 2, "ambient": {"levle": 0.1}})
    with pytest.raises(RigError, match=r"'sim\.ambient\.level' is -1"):
        SimRig({"scene": "blob", "subdivisions": 2, "ambient": {"level": -1}})


def _decoded(folder, view: int, label: str, image: np.ndarray, exposure_s: float):
    from reconstruct.frames.decode import DecodedFrame

    stem = f"v{view}_{label}"
    np.save(folder / f"{stem}.npy", image.astype(np.float32))
    np.save(folder / f"{stem}_sat.npy", np.zeros(image.shape[:2], dtype=bool))
    h, w = image.shape[:2]
    return DecodedFrame(
        0, view, label, f"{stem}.npy", f"{stem}_sat.npy", "x.dng", exposure_s, 100.0, h, w, 0.0
    )


def test_pipeline_subtracts_the_views_ambient_frame(tmp_path, pair):
    from types import SimpleNamespace

    from reconstruct.run.pipeline import lit_frame

    dark, room = pair
    assert room.ambient_images is not None and room.frames.images is not None
    assert dark.frames.images is not None
    frames = {
        (0, "LED1"): _decoded(tmp_path, 0, "LED1", room.frames.images[0], 0.5),
        (0, "ambient"): _decoded(tmp_path, 0, "ambient", room.ambient_images[0] / 4, 0.125),
        (1, "LED1"): _decoded(tmp_path, 1, "LED1", room.frames.images[2], 0.5),
    }
    front = SimpleNamespace(frames=frames, decoded_dir=tmp_path,
                            levels=SimpleNamespace(optimise_step=0))
    image, sat, weight = lit_frame(front, (0, "LED1"))  # type: ignore[arg-type]
    np.testing.assert_allclose(image, dark.frames.images[0], atol=1e-5)
    assert weight < 1.0 and not sat.any()
    image, _, weight = lit_frame(front, (1, "LED1"))  # type: ignore[arg-type]
    np.testing.assert_array_equal(image, room.frames.images[2])  # no ambient frame: as is
    assert weight == 1.0
