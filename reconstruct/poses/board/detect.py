"""Finding the board in an image: sub-pixel ChArUco corners and a visibility check.

Corner coordinates follow COLMAP's pixel convention (centre of the top-left pixel at
(0.5, 0.5)); OpenCV's detector works with the centre at (0, 0), so 0.5 is added once here.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from core.errors import RigError
from reconstruct.poses.board.spec import BoardSpec


@dataclass(frozen=True)
class Detection:
    """ChArUco corners seen in one image: ids, pixel positions (N, 2), world points (N, 3);
    plus the decoded markers (ids (M,), corners (M, 4, 2)), coarser but found more often."""

    ids: np.ndarray
    corners: np.ndarray
    object_points: np.ndarray
    image_size: tuple[int, int]  # (width, height)
    marker_ids: np.ndarray
    marker_corners: np.ndarray

    @property
    def n_corners(self) -> int:
        return len(self.ids)

    @property
    def n_markers(self) -> int:
        return len(self.marker_ids)


def _gray_u8(image: np.ndarray) -> np.ndarray:
    if image.dtype != np.uint8:
        raise RigError(
            f"board detection needs an 8-bit image, got {image.dtype}",
            "convert linear frames with reconstruct.poses.board.linear_to_u8 first",
        )
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    if image.ndim != 2:
        raise RigError(
            f"board detection got an image of shape {image.shape}",
            "pass a grey (H, W) or RGB (H, W, 3) image",
        )
    return image


def linear_to_u8(image: np.ndarray, percentile: float = 99.5) -> np.ndarray:
    """Linear camera values -> 8-bit display values (scaled to a high percentile, gamma 1/2.2)
    so the marker detector's thresholds work on frames of any exposure. NaNs count as 0."""
    img = np.nan_to_num(np.asarray(image, dtype=float))
    if img.ndim == 3:
        img = img.mean(axis=2)
    top = np.percentile(img, percentile)
    scaled = np.clip(img / top, 0.0, 1.0) if top > 0 else np.zeros_like(img)
    return np.round(255.0 * scaled ** (1 / 2.2)).astype(np.uint8)


@functools.lru_cache(maxsize=8)
def _detector(spec: BoardSpec) -> cv2.aruco.CharucoDetector:
    charuco = cv2.aruco.CharucoParameters()
    charuco.tryRefineMarkers = True  # re-finds markers the first pass missed, from the board layout
    detector = cv2.aruco.DetectorParameters()
    return cv2.aruco.CharucoDetector(spec.cv_board(), charuco, detector)


def detect_board(image_u8: np.ndarray, spec: BoardSpec) -> Detection:
    """Detect the ChArUco corners in an 8-bit grey or RGB image (any number, possibly none)."""
    gray = _gray_u8(image_u8)
    corners, ids, marker_corners, marker_ids = _detector(spec).detectBoard(gray)
    size = (int(gray.shape[1]), int(gray.shape[0]))
    if marker_ids is None or len(marker_ids) == 0:
        m_ids, m_uv = np.zeros(0, int), np.zeros((0, 4, 2))
    else:
        m_ids = np.asarray(marker_ids, dtype=int).ravel()
        m_uv = np.asarray(marker_corners, dtype=float).reshape(-1, 4, 2) + 0.5
    if ids is None or len(ids) == 0:
        return Detection(np.zeros(0, int), np.zeros((0, 2)), np.zeros((0, 3)), size, m_ids, m_uv)
    ids = np.asarray(ids, dtype=int).ravel()
    uv = np.asarray(corners, dtype=float).reshape(-1, 2) + 0.5
    return Detection(ids, uv, spec.corner_points()[ids], size, m_ids, m_uv)


def board_visibility_report(image_u8: np.ndarray, spec: BoardSpec) -> tuple[int, float]:
    """(corners found, contrast) for capture guidance.

    Contrast is (median paper - median ink) / 255, sampled at black-square centres and in the
    white rim of the marker squares through the board-to-image homography of the decoded
    markers and corners; 0.0 when no marker is decoded. Near 0 means the board is too dark,
    too bright (clipped) or out of focus.
    """
    gray = _gray_u8(image_u8)
    det = detect_board(gray, spec)
    if det.n_markers == 0:
        return det.n_corners, 0.0
    marker_world = spec.marker_points()[det.marker_ids].reshape(-1, 3)
    src = np.concatenate([marker_world[:, :2], det.object_points[:, :2]])
    dst = np.concatenate([det.marker_corners.reshape(-1, 2), det.corners])
    H, _ = cv2.findHomography(src, dst, cv2.RANSAC, 3.0)
    if H is None:
        return det.n_corners, 0.0
    ink, paper = _sample_points(spec)
    values = []
    for pts in (ink, paper):
        uv = cv2.perspectiveTransform(pts[None], H)[0] - 0.5
        col, row = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
        inside = (col >= 0) & (col < gray.shape[1]) & (row >= 0) & (row < gray.shape[0])
        if not inside.any():
            return det.n_corners, 0.0
        values.append(np.median(gray[row[inside], col[inside]]))
    return det.n_corners, float(max(0.0, (values[1] - values[0]) / 255.0))


def _sample_points(spec: BoardSpec) -> tuple[np.ndarray, np.ndarray]:
    """World (x, y) sample points on ink (black-square centres) and on paper (middle of the
    white rim beside each marker's sides)."""
    rects = spec.black_rectangles()
    sizes = rects[:, 2] - rects[:, 0]
    squares = rects[np.isclose(sizes, spec.square_m)]
    ink = np.stack([squares[:, [0, 2]].mean(axis=1), squares[:, [1, 3]].mean(axis=1)], axis=1)
    centres = spec.marker_points().mean(axis=1)[:, :2]
    rim = (spec.square_m + spec.marker_m) / 4  # centre -> middle of the white rim
    offsets = np.array([[rim, 0.0], [-rim, 0.0], [0.0, rim], [0.0, -rim]])
    paper = (centres[:, None, :] + offsets[None]).reshape(-1, 2)
    return ink.astype(np.float32), paper.astype(np.float32)
