"""Object silhouettes from linear frames of an object on a dark background.

The rig photographs the object lit by a lamp beside the lens; the background is far and
dark, so the brightest pixels of each view (over all its illuminations) are the object.
Otsu's threshold on a gamma tone map finds the background, whose noise spread then sets
the threshold; holes inside the outline (dark paint,
attached shadows) are filled, since a silhouette is about the outline only.
"""

from __future__ import annotations

import cv2
import numpy as np


def silhouette(images: list[np.ndarray], open_px: int = 2) -> np.ndarray:
    """Linear RGB images of one view -> bool foreground mask (H, W)."""
    u8 = tone_map(np.max([img.sum(axis=2) for img in images], axis=0))
    mask: np.ndarray = np.where(u8 > dark_level(u8), 255, 0).astype(np.uint8)
    if open_px:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * open_px + 1,) * 2)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
    return fill_holes(mask > 0)


def tone_map(brightness: np.ndarray) -> np.ndarray:
    """Linear brightness -> uint8 on a gamma curve (the 99.9th percentile white), so the
    dark background's noise and the object's range both get levels."""
    top = float(np.percentile(brightness, 99.9)) or 1.0
    return (np.clip(brightness / top, 0.0, 1.0) ** (1.0 / 2.2) * 255.0).astype(np.uint8)


def dark_level(u8: np.ndarray) -> float:
    """Threshold above which a tone-mapped pixel is object rather than dark background.

    The background is the darkest mode of the image: its level and noise spread are the
    median and MAD of the pixels in Otsu's lower class (robust while the background fills
    more of that class than the object's dark paint and shadows do). Otsu's own split
    halfway loses the object's dark limb and dark paint, and a mean + std of the lower
    class is inflated by them (on a ColorChecker-painted scan a black patch read as
    background and carved the visual hull 10 mm into the object)."""
    values = np.ascontiguousarray(u8.reshape(-1, 1))
    otsu, _ = cv2.threshold(values, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    background = values[values <= otsu].astype(float)
    level = float(np.median(background))
    spread = 1.4826 * float(np.median(np.abs(background - level)))
    return float(min(otsu, level + 6.0 * max(spread, 1.0) + 1.0))


def fill_holes(mask: np.ndarray) -> np.ndarray:
    """Everything not reachable from the image border through background is foreground."""
    h, w = mask.shape
    padded = np.zeros((h + 2, w + 2), np.uint8)
    padded[1:-1, 1:-1] = mask.astype(np.uint8)
    flood = np.zeros((h + 4, w + 4), np.uint8)
    cv2.floodFill(padded, flood, (0, 0), 2)
    return np.asarray(padded[1:-1, 1:-1] != 2)
