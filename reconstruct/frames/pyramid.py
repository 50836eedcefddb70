"""Images and saturation masks at a coarser pyramid level (each level halves the size;
:mod:`reconstruct.stages.resolution` chooses the level).

Images are area-averaged (``cv2.INTER_AREA``: every source pixel counts by its overlap, the
mean light over the coarse pixel). Masks are conservative: a coarse pixel is saturated when any
source pixel it covers was. Sizes round as :func:`reconstruct.stages.resolution.level_size`,
so intrinsics scaled by the width and height ratios (COLMAP's pixel-corner convention,
:func:`reconstruct.poses.sfm.rescale`) stay exact.
"""

from __future__ import annotations

import cv2
import numpy as np

from reconstruct.stages.resolution import level_size


def resize_area(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``image`` (H, W) or (H, W, C) area-averaged to ``size`` (width, height), as float32."""
    image = np.asarray(image, dtype=np.float32)
    if image.shape[1::-1] == size:
        return image
    out = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    return np.asarray(out).reshape(size[1], size[0], *image.shape[2:])


def resize_mask(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Boolean ``mask`` (H, W) shrunk to ``size``: True where any covered pixel is."""
    return resize_area(mask.astype(np.float32), size) > 0.0


def downsample(image: np.ndarray, steps: int) -> np.ndarray:
    """``image`` halved ``steps`` times, area-averaged, as float32."""
    h, w = image.shape[:2]
    return resize_area(image, level_size(w, h, steps))


def downsample_mask(mask: np.ndarray, steps: int) -> np.ndarray:
    """Boolean ``mask`` halved ``steps`` times, conservatively."""
    h, w = mask.shape[:2]
    return resize_mask(mask, level_size(w, h, steps))
