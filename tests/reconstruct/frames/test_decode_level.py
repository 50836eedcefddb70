"""Decode at a pyramid level: the size the preset allows, values area-averaged from the full
decode, saturation masks conservative (a pixel is saturated if any source pixel was)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rawpy

from reconstruct.frames.decode import centre_half_size, decode_raw, decode_raw_level
from reconstruct.frames.pyramid import downsample, downsample_mask, resize_mask


@pytest.mark.parametrize(("max_side", "level", "size"), [(1000, 1, (867, 578)),
                                                          (500, 2, (434, 289))])
def test_raw_decoded_at_the_level_the_preset_allows(
    shared_data: Path, max_side: int, level: int, size: tuple[int, int]
) -> None:
    path = shared_data / "raw" / "colorchart.dng"
    full, full_mask = decode_raw(path, "linear", 0.7)
    rgb, mask, got = decode_raw_level(path, "linear", 0.7, max_side)
    assert got == level and rgb.shape == (size[1], size[0], 3) and mask.shape == rgb.shape[:2]
    assert rgb.dtype == np.float32
    # the half-size demosaic, area-averaged, is the full decode area-averaged (bar edges)
    reference = downsample(full, level)
    flat = ~downsample_mask(full_mask, level)
    assert np.median(np.abs(rgb - reference)[flat]) < 2e-3
    np.testing.assert_allclose(rgb[flat].mean(0), reference[flat].mean(0), rtol=0.01)
    # conservative: every pixel covering a clipped mosaic sample is saturated
    with rawpy.imread(str(path)) as raw:
        clipped = raw.raw_image_visible >= 2056 + 0.7 * (15000 - 2056)
    assert clipped.any()
    assert mask[resize_mask(clipped, size)].all()
    assert mask.mean() < 0.5


def test_pyramid_masks_are_conservative_and_images_keep_the_mean() -> None:
    rng = np.random.default_rng(1)
    mask = np.zeros((97, 131), bool)
    mask[40, 77] = True  # one saturated pixel
    small = downsample_mask(mask, 2)
    assert small.shape == (24, 33) and small.sum() in (1, 2, 4)  # its coarse pixel(s) only
    assert small[40 * 24 // 97, 77 * 33 // 131]
    image = rng.uniform(0, 1, (96, 128, 3))
    half = downsample(image, 1)
    np.testing.assert_allclose(half, image.reshape(48, 2, 64, 2, 3).mean((1, 3)), atol=1e-6)


def test_half_size_channels_are_moved_to_the_pixel_centre() -> None:
    """On a linear ramp the half-size red (top-left sample), greens (mean of two) and blue
    (bottom-right) all read the block's centre after re-centring."""
    h, w = 12, 16
    ramp = lambda x, y: 0.01 * x + 0.003 * y  # noqa: E731 (full-size pixel coordinates)
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    half = np.stack([ramp(2 * xx + 0.5, 2 * yy + 0.5), ramp(2 * xx + 1.0, 2 * yy + 1.0),
                     ramp(2 * xx + 1.5, 2 * yy + 1.5)], axis=-1).astype(np.float32)
    centred = centre_half_size(half, np.array([[0, 1], [3, 2]]), "RGBG")
    inner = (slice(1, -1), slice(1, -1))
    for c in range(3):
        np.testing.assert_allclose(centred[inner][..., c], half[inner][..., 1], atol=1e-6)
    assert np.abs(half[..., 0] - half[..., 1]).max() > 0.005  # it was off before
    # BGGR: blue top-left, red bottom-right
    flipped = centre_half_size(half[..., ::-1].copy(), np.array([[0, 1], [3, 2]]), "BGRG")
    np.testing.assert_allclose(flipped[inner][..., 0], half[inner][..., 1], atol=1e-6)
