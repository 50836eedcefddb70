"""The sim's DNG writer produces files LibRaw (rawpy) reads with the right levels and CFA."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rawpy
import tifffile

from core.errors import RigError
from drivers.sim.dng import write_dng
from reconstruct.frames.raw import postprocess_linear

BLACK, WHITE = 512, 16383


def _write(path: Path, mosaic: np.ndarray, pattern: str = "RGGB") -> None:
    write_dng(
        path,
        mosaic,
        pattern=pattern,
        black_level=BLACK,
        white_level=WHITE,
        exposure_s=0.25,
        iso=400,
        make="spectral-rig",
        model="Test",
        serial="T-1",
        color_matrix=np.array([[0.9, -0.2, 0.1], [-0.3, 1.1, 0.2], [0.0, 0.1, 0.6]]),
        as_shot_neutral=np.array([0.5, 1.0, 0.7]),
    )


def decode(path: Path) -> np.ndarray:
    """The decode stage's own LibRaw call: linear camera RGB, 16-bit."""
    with rawpy.imread(str(path)) as raw:
        return postprocess_linear(raw, "linear")


def test_rawpy_reads_levels_pattern_and_values(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    mosaic = rng.integers(BLACK, WHITE + 1, size=(48, 64)).astype(np.uint16)
    mosaic[0, 0] = WHITE
    _write(tmp_path / "a.dng", mosaic)
    with rawpy.imread(str(tmp_path / "a.dng")) as raw:
        np.testing.assert_array_equal(raw.raw_image, mosaic)
        assert list(raw.black_level_per_channel) == [BLACK] * 4
        assert raw.white_level == WHITE
        np.testing.assert_array_equal(raw.raw_pattern, [[0, 1], [3, 2]])
        assert raw.color_desc == b"RGBG"
        assert (raw.sizes.width, raw.sizes.height, raw.sizes.flip) == (64, 48, 0)
    rgb = decode(tmp_path / "a.dng").astype(float)
    # At each site its own channel is passed through: 65535 (raw - black) / (white - black).
    scaled = 65535 * (mosaic.astype(float) - BLACK) / (WHITE - BLACK)
    np.testing.assert_allclose(rgb[0::2, 0::2, 0], scaled[0::2, 0::2], atol=1.0)
    np.testing.assert_allclose(rgb[0::2, 1::2, 1], scaled[0::2, 1::2], atol=1.0)
    np.testing.assert_allclose(rgb[1::2, 1::2, 2], scaled[1::2, 1::2], atol=1.0)


def test_bggr_pattern_and_exif(tmp_path: Path) -> None:
    mosaic = np.full((32, 32), 1000, np.uint16)
    _write(tmp_path / "b.dng", mosaic, pattern="BGGR")
    with rawpy.imread(str(tmp_path / "b.dng")) as raw:
        np.testing.assert_array_equal(raw.raw_pattern, [[2, 3], [1, 0]])
    tags = tifffile.TiffFile(tmp_path / "b.dng").pages[0].tags
    assert tags["ExposureTime"].value == (1, 4)
    assert tags["ISOSpeedRatings"].value == 400
    assert tags["DNGVersion"].value == b"\x01\x04\x00\x00"
    assert tags["PhotometricInterpretation"].value == 32803
    assert tags["UniqueCameraModel"].value == "spectral-rig Test"


def test_bad_mosaic_is_refused(tmp_path: Path) -> None:
    with pytest.raises(RigError, match="uint16"):
        _write(tmp_path / "c.dng", np.zeros((33, 32), np.uint16))
    with pytest.raises(RigError, match="Bayer"):
        _write(tmp_path / "c.dng", np.zeros((32, 32), np.uint16), pattern="RGBX")
