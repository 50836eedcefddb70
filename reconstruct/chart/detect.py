"""Finding a colour chart in a linear camera-RGB image with OpenCV's Macbeth chart detector
(``cv2.mcc``).

The detector works on 8-bit BGR images and tells the chart's orientation from the colours it
sees, so it is shown a grey-world balanced, tone-mapped copy; the values are read afterwards
from the linear image (:mod:`reconstruct.chart.patches`). Its contour clustering draws from
OpenCV's global random generator, so each attempt is seeded: the result is reproducible, and a
miss on one seed is retried on the next.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from core.errors import RigError

ATTEMPTS = 4  # seeds tried per tone-mapped copy before that copy counts as chartless


@dataclass(frozen=True)
class Layout:
    """A chart's patch grid (row-major from the top-left patch) and its detector type."""

    name: str
    rows: int
    cols: int
    mcc_type: int

    @property
    def size(self) -> int:
        return self.rows * self.cols


LAYOUTS = {"classic24": Layout("classic24", 4, 6, cv2.mcc.MCC24)}


@dataclass(frozen=True)
class ChartGeometry:
    """Where the chart lies in the image, in the project's pixel convention (pixel ``[r, c]``
    covers ``[c, c+1) × [r, r+1)``): ``patches`` (N, 4, 2) each patch's corners (x, y) in
    chart order, ``corners`` (4, 2) the outer corners of the top-left, top-right,
    bottom-right and bottom-left patches, ``cost`` the detector's fit residual."""

    patches: np.ndarray
    corners: np.ndarray
    cost: float


def layout(name: str) -> Layout:
    """A known chart layout by name, or one error listing them."""
    if name not in LAYOUTS:
        raise RigError(f"unknown chart layout {name!r}", f"use one of {', '.join(LAYOUTS)}")
    return LAYOUTS[name]


def detection_images(rgb: np.ndarray) -> list[np.ndarray]:
    """8-bit BGR copies for the detector: grey-world balanced first (the detector matches sRGB
    colours, and camera RGB without white balance is green), then unbalanced."""
    linear = np.nan_to_num(np.asarray(rgb, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    linear = np.maximum(linear, 0.0)
    means = linear.reshape(-1, 3).mean(axis=0)
    balanced = linear / np.where(means > 0, means / max(float(means.max()), 1e-30), 1.0)
    return [_tone_map(balanced), _tone_map(linear)]


def _tone_map(linear: np.ndarray) -> np.ndarray:
    scale = float(np.percentile(linear, 99.5)) or 1.0
    u8 = (np.clip(linear / scale, 0.0, 1.0) ** (1.0 / 2.2) * 255.0 + 0.5).astype(np.uint8)
    return np.ascontiguousarray(u8[:, :, ::-1])


def _detect_one(bgr: np.ndarray, chart: Layout) -> ChartGeometry | None:
    for seed in range(ATTEMPTS):
        cv2.setRNGSeed(seed)
        detector = cv2.mcc.CCheckerDetector.create()
        detector.setColorChartType(chart.mcc_type)
        if not detector.process(bgr, 1):
            continue  # the detector then has no checker: asking for one would crash it
        found = detector.getBestColorChecker()
        quads = np.asarray(found.getColorCharts(), dtype=float).reshape(chart.size, 4, 2)
        quads += 0.5  # OpenCV puts pixel centres on integers, the project at +0.5
        c = chart.cols
        corners = np.array(
            [quads[0, 0], quads[c - 1, 1], quads[chart.size - 1, 2], quads[chart.size - c, 3]]
        )
        return ChartGeometry(quads, corners, float(found.getCost()))
    return None


def detect_chart(rgb: np.ndarray, chart: Layout) -> ChartGeometry | None:
    """The chart in a linear RGB image (H, W, 3), or None when the detector finds none: the
    lowest-cost detection over the tone-mapped copies of :func:`detection_images`."""
    found = [_detect_one(bgr, chart) for bgr in detection_images(rgb)]
    hits = [g for g in found if g is not None]
    return min(hits, key=lambda g: g.cost) if hits else None
