"""Chart detection and patch reading on a real camera RAW (a Canon EOS 550D DNG of a
ColorChecker Classic in ../shared/data/raw)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import RigError
from reconstruct.chart import read_patches, read_patches_linear
from reconstruct.chart.detect import LAYOUTS
from rig.commands.check_chart import LAYOUTS as CLI_LAYOUTS


@pytest.fixture(scope="module")
def real(shared_data: Path):
    return read_patches(shared_data / "raw" / "colorchart.dng")


def test_the_chart_is_found_where_it_is(real) -> None:
    # the chart's patches lie in x 650–1320, y 560–990 of the 1734 x 1156 frame
    assert real.rgb.shape == real.spread.shape == (24, 3)
    assert real.corners.shape == (4, 2)
    assert np.all((real.corners[:, 0] > 600) & (real.corners[:, 0] < 1350))
    assert np.all((real.corners[:, 1] > 540) & (real.corners[:, 1] < 1000))
    top_left, top_right, bottom_right, bottom_left = real.corners
    assert top_left[0] < top_right[0] and bottom_left[0] < bottom_right[0]
    assert top_left[1] < bottom_left[1] and top_right[1] < bottom_right[1]
    assert np.all(real.pixels > 300)


def test_the_neutral_row_darkens_from_white_to_black(real) -> None:
    neutral = real.rgb[18:24]
    assert np.all(np.diff(neutral, axis=0) < 0)
    assert np.all(real.spread[18:24] < neutral)  # the patch interiors are uniform


def test_the_primaries_have_their_dominant_channel(real) -> None:
    balanced = real.rgb / real.rgb[19]  # camera RGB white-balanced on neutral 8
    blue, green, red, yellow = balanced[12], balanced[13], balanced[14], balanced[15]
    assert np.argmax(blue) == 2 and np.argmax(green) == 1 and np.argmax(red) == 0
    assert min(yellow[0], yellow[1]) > 2 * yellow[2]


def test_values_are_the_raw_scale_without_white_balance(real, shared_data: Path) -> None:
    from reconstruct.frames.decode import DecodeConfig, decode_raw

    rgb, sat = decode_raw(shared_data / "raw" / "colorchart.dng", DecodeConfig().demosaic, 0.98)
    again = read_patches_linear(rgb, saturated=sat)
    np.testing.assert_allclose(again.rgb, real.rgb)
    doubled = read_patches_linear(2 * rgb, saturated=sat)  # detection ignores the scale
    np.testing.assert_allclose(doubled.rgb, 2 * real.rgb, rtol=1e-6)


def test_no_chart_is_one_error_naming_the_source() -> None:
    rng = np.random.default_rng(0)
    noise = rng.uniform(0.0, 1.0, (300, 400, 3)).astype(np.float32)
    with pytest.raises(RigError, match=r"no classic24 colour chart found in noise\.dng"):
        read_patches_linear(noise, source="noise.dng")


def test_a_missing_raw_names_the_file(tmp_path: Path) -> None:
    with pytest.raises(RigError, match="nothing.dng does not exist"):
        read_patches(tmp_path / "nothing.dng")


def test_the_cli_lists_the_detectors_layouts() -> None:
    assert tuple(LAYOUTS) == CLI_LAYOUTS
