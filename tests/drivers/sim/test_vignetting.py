"""The sim lens's fall-off switch: cos⁴ of the angle off the axis times 1 − extra·r², applied
to what the camera writes, and the white card it photographs for the flat field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.config import from_mapping
from core.errors import RigError
from drivers.sim.camera import SensorConfig, VignettingConfig
from drivers.sim.rig import SimRig
from drivers.sim.white_card import card_distance, white_card
from reconstruct.frames.decode import decode_raw
from reconstruct.model.camera import Intrinsics


def test_fall_off_is_cos4_times_the_lens_polynomial() -> None:
    intr = Intrinsics.pinhole(200, 100, 100.0)
    gain = VignettingConfig(cos4=True, extra=0.2).gain(intr)
    assert gain[49:51, 99:101] == pytest.approx(1.0, abs=1e-3)
    x, y = 99.5, 49.5  # the top-left pixel's centre off the axis, px
    cos = 100.0 / np.sqrt(100.0**2 + x**2 + y**2)
    r2 = (x**2 + y**2) / ((200**2 + 100**2) / 4)
    assert gain[0, 0] == pytest.approx(cos**4 * (1 - 0.2 * r2), rel=1e-9)
    assert VignettingConfig().gain(intr) == pytest.approx(np.ones((100, 200)))
    with pytest.raises(RigError, match="extra"):
        from_mapping(SensorConfig, {"vignetting": {"extra": 2.0}}, "sim", "sim.camera")


def test_the_white_card_fills_the_frame_and_darkens_with_the_lens(tmp_path: Path) -> None:
    camera = {"width": 96, "height": 64, "focal_px": 40.0, "supersample": 1,
              "exposure_s": 0.1}
    means = []
    for vignetting in (None, {"cos4": True, "extra": 0.3}):
        rig = SimRig({"scene": "chart", "subdivisions": 0,
                      "camera": {**camera, "vignetting": vignetting}})
        card = white_card(rig, 1)
        assert card.distance_m == card_distance(rig) < 0.3  # a wide lens: the card comes closer
        card.light.set_levels({"w": 1.0})
        rgb, saturated = decode_raw(card.camera.capture(tmp_path, "card").paths[0], "linear", 0.98)
        card.close()
        assert not saturated.any() and rgb[..., 1].min() > 0  # the card everywhere, lit
        means.append(rgb[:8, :8, 1].mean() / rgb[28:36, 44:52, 1].mean())
    assert means[1] < 0.75 * means[0]
