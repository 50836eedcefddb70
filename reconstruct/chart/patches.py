"""Per-patch linear camera RGB of a colour chart: the median over each patch's interior and its
spread, read from the linear image where :mod:`reconstruct.chart.detect` found the chart."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from core.errors import RigError
from reconstruct.chart.detect import ChartGeometry, detect_chart, layout
from reconstruct.frames.decode import DecodeConfig, decode_raw

log = logging.getLogger("reconstruct.chart")

INTERIOR = 0.5  # fraction of each patch's side read: its edges blur into the border
MAD_TO_SIGMA = 1.4826  # the median absolute deviation of a normal distribution, times this


@dataclass(frozen=True)
class ChartPatches:
    """A chart's patches in chart order (row-major from the top-left patch).

    ``rgb`` (N, 3): median linear camera RGB over each patch's interior, in the image's own
    scale (for a RAW: ``(raw - black) / (white - black)``, no white balance), NaN where every
    pixel is saturated; ``spread`` (N, 3): the robust standard deviation (1.4826 × MAD) of
    the same pixels; ``corners`` (4, 2): the chart's corners in pixels (x, y), top-left,
    top-right, bottom-right, bottom-left of the chart; ``patch_corners`` (N, 4, 2); ``pixels``
    (N,): unsaturated pixels read per patch."""

    rgb: np.ndarray
    spread: np.ndarray
    corners: np.ndarray
    patch_corners: np.ndarray
    pixels: np.ndarray


def interior_mask(quad: np.ndarray, shape: tuple[int, int], fraction: float) -> np.ndarray:
    """Pixels (H, W) whose centres lie in ``quad`` (4, 2, project convention) shrunk about its
    centroid to ``fraction`` of its size."""
    centre = quad.mean(axis=0)
    inner = centre + fraction * (quad - centre) - 0.5  # to OpenCV's integer pixel centres
    mask = np.zeros(shape, dtype=np.uint8)
    shift = 4  # sub-pixel vertices, in 1/16 pixel
    cv2.fillConvexPoly(mask, np.round(inner * (1 << shift)).astype(np.int32), 1, cv2.LINE_8, shift)
    return mask.astype(bool)


def read_values(
    rgb: np.ndarray, geometry: ChartGeometry, saturated: np.ndarray | None = None
) -> ChartPatches:
    """The patches' statistics from a linear image where ``geometry`` says they are."""
    image = np.asarray(rgb, dtype=np.float32)
    usable = np.ones(image.shape[:2], bool) if saturated is None else ~np.asarray(saturated)
    n = len(geometry.patches)
    medians, spreads = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    pixels = np.zeros(n, dtype=int)
    for k, quad in enumerate(geometry.patches):
        sel = interior_mask(quad, image.shape[:2], INTERIOR) & usable
        values = image[sel].astype(float)
        pixels[k] = len(values)
        if len(values):
            medians[k] = np.median(values, axis=0)
            spreads[k] = MAD_TO_SIGMA * np.median(np.abs(values - medians[k]), axis=0)
    return ChartPatches(medians, spreads, geometry.corners, geometry.patches, pixels)


def read_patches_linear(
    rgb: np.ndarray,
    *,
    layout: str = "classic24",
    saturated: np.ndarray | None = None,
    source: str = "the image",
) -> ChartPatches:
    """The chart's patches in a linear camera-RGB image (H, W, 3); ``saturated`` (H, W) marks
    pixels never read. No chart found is a RigError naming ``source``."""
    geometry = find_chart(rgb, layout, source)
    return read_values(rgb, geometry, saturated)


def find_chart(rgb: np.ndarray, layout_name: str, source: str) -> ChartGeometry:
    """The chart's geometry in a linear image, or one error naming ``source``."""
    chart = layout(layout_name)
    geometry = detect_chart(rgb, chart)
    if geometry is None:
        raise RigError(
            f"no {chart.name} colour chart found in {source}",
            "frame the whole chart, lit evenly, facing the camera, patches at least 20 px wide",
        )
    return geometry


def read_patches(raw_path: Path, *, layout: str = "classic24") -> ChartPatches:
    """The chart's patches in a RAW file, decoded as the decode stage does (the one RAW reader,
    LibRaw's demosaic, no white balance, saturated pixels left out), in the RAW's own scale
    ``(raw - black) / (white - black)``."""
    path = Path(raw_path)
    if not path.is_file():
        raise RigError(f"RAW file {path} does not exist", "give the path of a camera RAW file")
    conf = DecodeConfig()
    try:
        rgb, saturated = decode_raw(path, conf.demosaic, conf.saturation)
    except Exception as exc:  # LibRaw's errors are not a common type
        raise RigError(f"cannot decode {path}: {exc}", "give a camera RAW file") from exc
    return read_patches_linear(rgb, layout=layout, saturated=saturated, source=str(path))
