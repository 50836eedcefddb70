"""The one RAW reader: a camera RAW file through LibRaw (rawpy) -> the visible sensor mosaic
with what it takes to turn it into light, ``(raw - black) / (white - black)``.

Every RAW consumer reads through here: the decode stage (demosaiced linear RGB and the
saturation mask), the capture's verify and exposure checks, and the wizard's reference patch.
LibRaw's demosaic is told not to stretch the histogram (``no_auto_bright``,
``adjust_maximum_thr=0``), otherwise the gain would change from shot to shot; its 16-bit output
is then exactly ``65535 (raw - black) / (white - black)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rawpy

DEMOSAIC = {
    "linear": rawpy.DemosaicAlgorithm.LINEAR,
    "vng": rawpy.DemosaicAlgorithm.VNG,
    "ppg": rawpy.DemosaicAlgorithm.PPG,
    "ahd": rawpy.DemosaicAlgorithm.AHD,
    "dcb": rawpy.DemosaicAlgorithm.DCB,
    "dht": rawpy.DemosaicAlgorithm.DHT,
    "aahd": rawpy.DemosaicAlgorithm.AAHD,
}
Window = tuple[slice, slice]
WHOLE: Window = (slice(None), slice(None))


@dataclass(frozen=True)
class RawMosaic:
    """The visible sensor area of a RAW file, not demosaiced.

    ``values`` (H, W) as stored (e.g. uint16); ``colours`` (H, W) each pixel's filter colour,
    an index into ``colour_desc`` (e.g. ``RGBG``) and ``channel_black``; ``white`` the
    saturation level; ``pattern`` one period of the colour-filter mosaic (None for sensors
    without one); ``camera_wb`` the camera's white-balance multipliers per colour index."""

    values: np.ndarray
    colours: np.ndarray
    channel_black: np.ndarray
    white: float
    colour_desc: str
    pattern: np.ndarray | None
    camera_wb: np.ndarray

    @property
    def mean_black(self) -> float:
        """One black level for the whole frame (the mean over the colour channels)."""
        return float(np.mean(self.channel_black))

    def black(self, window: Window = WHOLE, dtype: type = np.float32) -> np.ndarray:
        """Per-pixel black level of ``window``."""
        return self.channel_black.astype(dtype)[self.colours[window]]

    def levels(self, window: Window = WHOLE, dtype: type = np.float32) -> np.ndarray:
        """``(raw - black) / (white - black)`` per pixel of ``window``: 0 black, 1 clipped."""
        black = self.black(window, dtype)
        return (self.values[window].astype(dtype) - black) / (dtype(self.white) - black)

    def clipped(self, fraction: float, window: Window = WHOLE) -> np.ndarray:
        """Pixels of ``window`` whose level is at or above ``fraction`` of full scale."""
        threshold = self.channel_black + fraction * (self.white - self.channel_black)
        if np.issubdtype(self.values.dtype, np.integer):
            # value >= x exactly when value >= ceil(x): compared in the samples' own type
            threshold = np.ceil(threshold).astype(self.values.dtype)
        return self.values[window] >= threshold[self.colours[window]]


def _mosaic(raw: rawpy.RawPy) -> RawMosaic:
    pattern = raw.raw_pattern
    return RawMosaic(
        values=raw.raw_image_visible.copy(),
        colours=raw.raw_colors_visible.copy(),
        channel_black=np.asarray(raw.black_level_per_channel, dtype=float),
        white=float(raw.white_level),
        colour_desc=raw.color_desc.decode(),
        pattern=None if pattern is None else np.asarray(pattern, dtype=np.intp),
        camera_wb=np.asarray(raw.camera_whitebalance, dtype=float),
    )


def read_mosaic(path: Path) -> RawMosaic:
    """The RAW file's visible mosaic and levels (no demosaicing)."""
    with rawpy.imread(str(path)) as raw:
        return _mosaic(raw)


def read_linear_rgb(
    path: Path, demosaic: str, half_size: Callable[[int, int], bool] | None = None
) -> tuple[RawMosaic, np.ndarray]:
    """The mosaic and LibRaw's demosaic of it (:func:`postprocess_linear`) as float32
    ``(raw - black) / (white - black)`` in camera RGB (H, W, 3), from one opening of the file;
    at half size (one pixel per 2×2 mosaic block) when ``half_size(width, height)`` of the
    mosaic says so."""
    with rawpy.imread(str(path)) as raw:
        mosaic = _mosaic(raw)
        height, width = mosaic.values.shape
        half = half_size is not None and half_size(width, height)
        rgb = postprocess_linear(raw, demosaic, half)
    return mosaic, rgb.astype(np.float32) / 65535.0


def postprocess_linear(raw: rawpy.RawPy, demosaic: str, half_size: bool = False) -> np.ndarray:
    """LibRaw's demosaic with nothing else: black subtracted, scaled so white = 65535, no white
    balance, no colour matrix, gamma 1, and a fixed maximum (``adjust_maximum_thr=0``) so the
    gain never changes from shot to shot. ``half_size``: each 2×2 mosaic block becomes one
    pixel (its samples, the two greens averaged; no interpolation, ~15× faster than AHD)."""
    return raw.postprocess(
        half_size=half_size,
        demosaic_algorithm=DEMOSAIC[demosaic],
        use_camera_wb=False,
        use_auto_wb=False,
        user_wb=[1.0, 1.0, 1.0, 1.0],
        output_color=rawpy.ColorSpace.raw,
        gamma=(1, 1),
        output_bps=16,
        no_auto_bright=True,
        adjust_maximum_thr=0.0,
        user_flip=0,
    )
