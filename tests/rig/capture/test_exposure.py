"""The exposure check on first frames: it judges the lit region (object, board), not the
whole frame, on a subsample of the mosaic."""

from __future__ import annotations

import numpy as np
import pytest

from rig.capture.frames import (
    SAMPLE_PIXELS,
    SATURATED_LIMIT,
    RawData,
    check_exposure,
    exposure_sample,
    format_shutter,
)

BLACK, WHITE = 512.0, 16383.0


def frame(levels: np.ndarray, seed: int = 0) -> RawData:
    """A 14-bit Bayer frame from levels (0 black, 1 white) with a little read noise."""
    rng = np.random.default_rng(seed)
    dn = BLACK + np.asarray(levels, dtype=float) * (WHITE - BLACK) + rng.normal(0, 3, levels.shape)
    values = np.clip(np.round(dn), 0, WHITE).astype(np.uint16)
    return RawData(values, BLACK, WHITE, np.full((2, 2), BLACK), np.full((2, 2), 1 / WHITE))


def object_on_black(
    level: float, share: float = 0.005, shape: tuple[int, int] = (480, 640)
) -> np.ndarray:
    """A disc covering ``share`` of a black frame, lit from 0.3x to 1x ``level`` across it."""
    h, w = shape
    yy, xx = np.mgrid[:h, :w]
    r = np.sqrt(share * h * w / np.pi)
    inside = (yy - h / 2) ** 2 + (xx - w / 2) ** 2 < r**2
    shading = 0.3 + 0.7 * (xx - (w / 2 - r)) / (2 * r)
    return np.where(inside, level * shading, 0.0)


def test_small_well_exposed_object_on_black_gets_no_warning() -> None:
    levels = object_on_black(0.6)
    check = check_exposure(frame(levels), "rgb", 0.5)
    assert check.suggestion is None
    assert check.lit_fraction == pytest.approx(0.005, rel=0.1)
    assert 0.5 < check.p99_level < 0.62
    # The whole frame's 99th percentile is black: judged whole, it would read as underexposed.
    assert np.percentile(levels, 99) < 0.1


def test_small_dim_object_on_black_is_underexposed() -> None:
    check = check_exposure(frame(object_on_black(0.05)), "red", 0.5)
    assert check.suggestion == (
        "red: underexposed (99 % of the lit pixels below 5 % of full scale) — lengthen the "
        "exposure 4 stops to 8 s"
    )


def test_small_clipped_object_on_black_is_overexposed() -> None:
    """A quarter of the object clipped, under 0.5 % of the frame: judged whole it would pass."""
    levels = object_on_black(1.25, share=0.015)
    assert np.mean(levels >= 1.0) < SATURATED_LIMIT
    check = check_exposure(frame(levels), "LED2", 1 / 30)
    assert 0.15 < check.saturated_fraction < 0.35
    assert check.suggestion is not None and "of the lit pixels saturated — quarter" in (
        check.suggestion
    )
    assert check.suggestion.endswith("to 1/120 s")


def test_whole_frame_checks() -> None:
    rng = np.random.default_rng(1)
    scene = rng.uniform(0.2, 0.7, (100, 100))
    scene[:10, :10] = 1.0  # 1 % clipped
    check = check_exposure(frame(scene), "LED2", 1 / 30)
    assert check.saturated_fraction == pytest.approx(0.01, abs=1e-4)
    assert (
        check.suggestion == "LED2: 1.0 % of the lit pixels saturated — halve the exposure to 1/60 s"
    )
    dim = check_exposure(frame(scene * 0.06), "A", 0.01)  # four stops under, everything lit
    assert dim.suggestion is not None and "99 % of the lit pixels below 6 %" in dim.suggestion
    fine = check_exposure(frame(np.linspace(0.0, 0.77, 10_000).reshape(100, 100)), "B", 0.01)
    assert fine.suggestion is None
    assert format_shutter(1 / 125) == "1/125 s" and format_shutter(2.0) == "2 s"


def test_nothing_lit_but_hot_pixels_is_underexposed() -> None:
    levels = np.full((200, 200), 0.008)
    levels[::50, ::50] = 1.0  # 16 hot pixels: 0.04 %, no object
    check = check_exposure(frame(levels), "LED1", 0.1)
    assert check.suggestion is not None
    assert "underexposed (nothing above 2 % of full scale)" in check.suggestion
    assert check.saturated_fraction < 0.001


def test_large_frames_are_subsampled_by_whole_bayer_periods() -> None:
    h, w = 3744, 5616  # a 21 MP camera
    tile = np.array([[1000, 6000], [6000, 11000]], dtype=np.uint16)  # R, G, G, B levels
    raw = RawData(np.tile(tile, (h // 2, w // 2)), BLACK, WHITE)
    raw = RawData(raw.values, BLACK, WHITE, np.full((2, 2), BLACK), np.ones((2, 2)))
    sample = exposure_sample(raw)
    assert SAMPLE_PIXELS / 2 < sample.size <= SAMPLE_PIXELS
    values = np.round(sample * (WHITE - BLACK) + BLACK).astype(int)
    counts = {int(v): int(n) for v, n in zip(*np.unique(values, return_counts=True), strict=True)}
    assert counts[1000] == counts[11000] == counts[6000] // 2  # each filter keeps its share
    full = check_exposure(RawData(raw.values, BLACK, WHITE), "x", 1.0)
    assert full.p99_level == pytest.approx((11000 - BLACK) / (WHITE - BLACK), rel=1e-4)
