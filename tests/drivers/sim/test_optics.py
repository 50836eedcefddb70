"""The sim rig's real-optics switches: a bulb with a size (soft shadow edges; the profile's
``light_mount.diameter_m`` by default) and a neutral gloss lobe (highlights in the lamp's own
colour), beside the lens fall-off of test_vignetting.py."""

from __future__ import annotations

import numpy as np
import pytest

from core.config import from_mapping
from core.errors import RigError
from drivers.device_set import DeviceSet
from drivers.sim.rig import SimConfig, SimRig
from drivers.sim.world import world_config
from reconstruct.model import forward

CAMERA = {"width": 96, "height": 72, "focal_px": 120.0, "supersample": 1}


def lit_image(config: dict[str, object], illumination: str = "LED2") -> np.ndarray:
    rig = SimRig({"views": 4, "camera": CAMERA, **config}, seed=1)
    rig.goto_view(1)
    rig.light.set_illumination(illumination)
    return rig.camera.render_linear()


def test_a_sized_bulb_softens_shadow_edges_and_nothing_else() -> None:
    torus = {"scene": "torus", "subdivisions": 4}
    point = lit_image(torus)
    bulb = lit_image({**torus, "light_diameter_m": 0.06})
    lit = point.sum(axis=2) > 0
    change = np.abs(bulb - point).sum(axis=2) / np.maximum(point.sum(axis=2), 1e-9)
    # where the whole bulb is seen the image is the point light's; a few edge pixels change
    assert np.median(change[lit]) < 1e-6
    assert 0 < np.mean(change[lit] > 0.05) < 0.2
    # shadowed for the point, partly lit by the bulb: the penumbra reaches into the umbra
    assert np.any((point.sum(axis=2) == 0) & (bulb.sum(axis=2) > 0))


def test_the_profile_gives_the_sim_bulb_its_size() -> None:
    config = world_config(DeviceSet(light_diameter_m=0.06))
    assert config["light_diameter_m"] == 0.06
    assert "light_diameter_m" not in world_config(DeviceSet())
    rig = SimRig({"views": 2, "camera": CAMERA, "scene": "chart", "subdivisions": 0, **config})
    assert rig.camera.bulb_radius_m == pytest.approx(0.03)
    with pytest.raises(RigError, match="light_diameter_m"):
        from_mapping(SimConfig, {"light_diameter_m": -1}, "sim config", "sim")


def test_gloss_adds_a_highlight_in_the_lamps_own_colour() -> None:
    chart = {"scene": "chart", "subdivisions": 0, "light_offset_m": [0.0, 0.0, 0.0],
             "trajectory": {"elevations_deg": [90.0], "radius_m": 0.4}}  # fmt: skip
    matte = lit_image(chart, "LED3")
    glossy = lit_image({**chart, "gloss": {"specular": 0.04, "alpha": 0.2}}, "LED3")
    highlight = glossy - matte
    assert np.all(highlight >= -1e-12)
    strong = highlight.sum(axis=2) > 0.5 * highlight.sum(axis=2).max()
    centre = np.array([CAMERA["height"], CAMERA["width"]]) / 2
    rows, cols = np.nonzero(strong)
    assert np.hypot(rows.mean() + 0.5 - centre[0], cols.mean() + 0.5 - centre[1]) < 4
    # neutral: the camera's RGB of the lamp itself, whatever paint it lies on
    rig = SimRig({"views": 4, "camera": CAMERA, **chart}, seed=1)
    rig.light.set_illumination("LED3")
    lamp = forward.response_matrix(rig.camera.sensitivity, rig.light.spd()).sum(axis=1)
    ratios = highlight[strong] / highlight[strong].sum(axis=1, keepdims=True)
    np.testing.assert_allclose(ratios, np.tile(lamp / lamp.sum(), (len(ratios), 1)), atol=1e-9)
