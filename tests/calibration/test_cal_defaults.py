"""Built-in spectra from colour-science and the radiometric convention of the bulb models."""

from __future__ import annotations

import numpy as np
import pytest

from calibration import defaults
from calibration.grid import DEFAULT_GRID, SpectralGrid
from core.errors import RigError


@pytest.mark.parametrize("name", defaults.camera_names())
def test_cameras_are_normalised_rgb(name: str) -> None:
    c = defaults.camera_sensitivity(name)
    assert c.shape == (31, 3) and c.max() == pytest.approx(1.0) and c.min() >= 0
    # R peaks at longer wavelengths than G, G longer than B
    peaks = DEFAULT_GRID.wavelengths[np.argmax(c, axis=0)]
    assert peaks[0] > peaks[1] > peaks[2]


def test_canon_comes_from_rawtoaces_dataset() -> None:
    w, rgb = defaults.camera_sensitivity_native("canon eos 5d mark ii")
    assert w[0] == 380 and w[-1] == 780 and rgb.shape == (w.size, 3)
    assert "rawtoaces" in defaults.camera_source_description("Canon EOS 5D Mark II")


def test_unknown_camera() -> None:
    with pytest.raises(RigError, match="unknown built-in camera 'Foo'"):
        defaults.camera_sensitivity("Foo")


def test_bulb_channels_follow_the_radiometric_convention() -> None:
    ch = defaults.rgbcw_channel_spds()
    assert list(ch) == ["r", "g", "b", "c", "w"]
    camera = defaults.camera_sensitivity()
    full = sum(ch.values())
    white = camera.T @ full / 0.5**2  # perfect white reflector at 0.5 m
    assert white.max() == pytest.approx(0.5)
    peaks = {k: DEFAULT_GRID.wavelengths[np.argmax(v)] for k, v in ch.items()}
    assert 610 <= peaks["r"] <= 640 and 510 <= peaks["g"] <= 540 and 440 <= peaks["b"] <= 470
    # equal radiant power per channel before scaling
    sums = [v.sum() for v in ch.values()]
    np.testing.assert_allclose(sums, sums[0])


def test_illuminations_are_channel_mixes() -> None:
    ch = defaults.rgbcw_channel_spds()
    ill = defaults.default_illuminations()
    assert set(ill) == {"LED1", "LED2", "LED3"}
    np.testing.assert_allclose(defaults.illumination_spd(ill["LED1"], ch), ch["c"])
    np.testing.assert_allclose(
        defaults.illumination_spd({"r": 0.5, "g": 1.0}, ch), 0.5 * ch["r"] + ch["g"]
    )
    with pytest.raises(RigError, match="unknown channel 'x'"):
        defaults.illumination_spd({"x": 1.0}, ch)
    with pytest.raises(RigError, match="outside 0..1"):
        defaults.illumination_spd({"r": 2.0}, ch)
    with pytest.raises(RigError, match="'r' level 'full' is not a number"):
        defaults.illumination_spd({"r": "full"}, ch)  # type: ignore[dict-item]


def test_reflectance_sets_and_illuminants() -> None:
    names, refl = defaults.colorchecker_reflectances()
    assert len(names) == 24 and refl.shape == (24, 31)
    assert names[18] == "white 9.5 (.05 D)" and refl[18].mean() > 0.85
    assert defaults.training_reflectances().shape == (214, 31)
    d65 = defaults.cie_illuminant("d65")
    assert d65.max() == pytest.approx(1.0)
    a = defaults.cie_illuminant("A", SpectralGrid(400, 700, 5))
    assert a.shape == (61,) and a[-1] == pytest.approx(1.0)  # A rises towards red
    with pytest.raises(RigError, match="unknown CIE illuminant"):
        defaults.cie_illuminant("D99")
