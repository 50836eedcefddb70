"""bench.calibration_costs: a stand-in calibration costs colour accuracy, the own one does not."""

from __future__ import annotations

import numpy as np
import pytest

from bench.calibration_costs import estimate_error, main
from bench.external_scene import DATA
from calibration import defaults


def test_a_stand_in_camera_costs_more_than_the_cameras_own_sensitivity() -> None:
    _, truth = defaults.colorchecker_reflectances()
    channels = defaults.rgbcw_channel_spds()
    lamps = [defaults.illumination_spd({"c": 1.0}, channels),
             defaults.illumination_spd({"w": 1.0}, channels)]
    canon = defaults.camera_sensitivity("Canon EOS 5D Mark II")
    nikon = defaults.camera_sensitivity("Nikon 5100")
    own = estimate_error(truth, nikon, lamps, nikon, lamps)
    stand_in = estimate_error(truth, nikon, lamps, canon, lamps)
    assert own.shape == (24,) and np.all(np.isfinite(own))
    assert stand_in.mean() > 1.5 * own.mean()


def test_the_table_prints_from_the_shared_data(capsys: pytest.CaptureFixture[str]) -> None:
    if not (DATA / "camera_ssf").is_dir():
        pytest.skip(f"no shared data at {DATA}")
    assert main([]) == 0
    out = capsys.readouterr().out
    assert "built-in bulb models" in out and "27 cameras" in out
