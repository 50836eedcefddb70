"""The board's printed appearance as an image in the world frame, for texturing a ground plane.

Each pixel holds the fraction of its area left as bare paper (1 = paper, 0 = ink), computed
exactly from the ink rectangles (a box filter), so a renderer sampling it sees no aliasing
from the rasterisation itself.
"""

from __future__ import annotations

import numpy as np

from core.errors import RigError
from reconstruct.poses.board.spec import BoardSpec


def _coverage_1d(
    lo: np.ndarray, hi: np.ndarray, origin: float, n: int, px_per_m: float
) -> np.ndarray:
    """Length (in pixels) of each interval [lo, hi] falling in each of ``n`` pixels starting
    at ``origin``: (M, n)."""
    edges = origin + np.arange(n + 1) / px_per_m
    left = np.maximum(lo[:, None], edges[None, :-1])
    right = np.minimum(hi[:, None], edges[None, 1:])
    return np.clip(right - left, 0.0, None) * px_per_m


def board_texture(
    spec: BoardSpec, px_per_m: float, margin_m: float | None = None
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """Printed board -> (image float [0, 1] of shape (H, W), extent (x0, y0, x1, y1) in metres).

    The image covers the sheet (``spec.paper``) or, without one, the board plus ``margin_m``
    of white paper (default one square). Row 0 is the top edge (y = y1), column 0 the left
    edge (x = x0): pixel (r, c) covers x in [x0 + c/px_per_m, x0 + (c+1)/px_per_m] and
    y in [y1 - (r+1)/px_per_m, y1 - r/px_per_m], like ``imshow(img, extent=(x0, x1, y0, y1))``.
    """
    if not px_per_m > 0:
        raise RigError(
            f"texture resolution {px_per_m} px/m is not positive",
            "use e.g. 4000 px/m (0.25 mm per pixel)",
        )
    paper = spec.paper_size_m()
    if paper is None:
        margin = spec.square_m if margin_m is None else margin_m
        bw, bh = spec.size_m
        paper = (bw + 2 * margin, bh + 2 * margin)
    width, height = (max(1, round(s * px_per_m)) for s in paper)
    if width * height > 64e6:
        raise RigError(
            f"a {width}x{height} px board texture is too large",
            "lower px_per_m (a quarter of a millimetre per pixel is plenty)",
        )
    x0, y1 = -width / (2 * px_per_m), height / (2 * px_per_m)
    rects = spec.black_rectangles()
    cover_x = _coverage_1d(rects[:, 0], rects[:, 2], x0, width, px_per_m)
    # Rows run downwards from y1: flip y into a distance from the top edge.
    cover_y = _coverage_1d(y1 - rects[:, 3], y1 - rects[:, 1], 0.0, height, px_per_m)
    ink = cover_y.T @ cover_x
    image = np.clip(1.0 - ink, 0.0, 1.0)
    return image, (x0, -y1, -x0, y1)
