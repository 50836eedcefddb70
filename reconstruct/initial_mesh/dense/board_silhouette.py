"""Object silhouettes when the object stands on a printed board (known texture, known pose).

A bright, high-contrast board defeats the dark-background rule. But with the board's pose
every pixel whose ray meets the sheet has a known printed albedo ``a`` (paper fraction from
:func:`board_texture`), and the ground obeys ``I = k(u, v) · (ε + (1 - ε) a)`` per channel,
where ``k`` is a smooth shading field (near lamp: inverse square times cosine, vignetting)
and ``ε`` the ink/paper ratio. Both are fitted per frame and channel on pixels the print
predicts to be clear paper (or ink), rejecting outliers (the object, its shadow) iteratively.
A pixel is object when its channels and frames together depart from the prediction by more
than their noise allows (with an allowance on printed edges, which demosaicing and pose error
blur, measured per view on the edges themselves); that includes the object's cast shadow, a
conservative error: it only enlarges that view's cone, other views carve it. Pixels off the
sheet keep the dark-background rule of :mod:`reconstruct.initial_mesh.dense.silhouette`.
"""

from __future__ import annotations

import functools
import logging

import cv2
import numpy as np
from numba import njit, prange

from reconstruct.initial_mesh.dense.silhouette import fill_holes, silhouette
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.poses.board import BoardSpec, board_texture

log = logging.getLogger("reconstruct.initial_mesh.dense")

TEXTURE_PX_PER_M = 4000.0  # 0.25 mm texels, finer than a pixel's footprint on the board
MIN_PAPER_PX = 200  # clear-paper pixels needed to fit the shading (10 coefficients)


@functools.lru_cache(maxsize=4)
def _texture(spec: BoardSpec) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    image, extent = board_texture(spec, TEXTURE_PX_PER_M)
    return image.astype(np.float32), extent


@functools.lru_cache(maxsize=2)
def _supersampled_rays(intrinsics: Intrinsics, supersample: int) -> np.ndarray:
    """Camera-frame rays through ``supersample``² points per pixel (H·W·ss², 3). A session's
    views share one camera, and undistorting millions of rays per view was most of the
    silhouette stage at 800×600."""
    ss = supersample
    rr, cc = np.mgrid[0 : intrinsics.height * ss, 0 : intrinsics.width * ss]
    uv = np.stack([(cc.ravel() + 0.5) / ss, (rr.ravel() + 0.5) / ss], axis=1)
    rays = intrinsics.pixel_rays(uv)
    rays.flags.writeable = False
    return rays


def expected_ground(
    spec: BoardSpec, intrinsics: Intrinsics, pose: Pose, supersample: int = 3
) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel: mean paper fraction of the sheet seen there and the fraction of the pixel
    that sees the sheet at all (both (H, W), box-filtered over ``supersample``² rays)."""
    texture, (x0, y0, x1, y1) = _texture(spec)
    ss = supersample
    h, w = intrinsics.height, intrinsics.width
    paper, cover = _ground_coverage(
        _supersampled_rays(intrinsics, ss), pose.R, pose.center, texture,
        np.array([x0, y0, x1, y1]), h, w, ss, TEXTURE_PX_PER_M,
    )
    return paper, cover


@njit(parallel=True, cache=True)
def _ground_coverage(
    rays: np.ndarray, R: np.ndarray, centre: np.ndarray, texture: np.ndarray,
    extent: np.ndarray, h: int, w: int, ss: int, texels_per_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Box-filtered paper fraction and sheet coverage per pixel: each camera ray (row-major
    over the (h·ss, w·ss) supersampled grid) turned to the world (``d @ R``) and met with the
    board plane z = 0 inside ``extent`` (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = extent[0], extent[1], extent[2], extent[3]
    th, tw = texture.shape
    paper = np.zeros((h, w), np.float32)
    cover = np.zeros((h, w), np.float32)
    inv = 1.0 / (ss * ss)
    for r in prange(h):
        for c in range(w):
            p_sum = 0.0
            n_on = 0
            for i in range(ss):
                base = (r * ss + i) * (w * ss) + c * ss
                for j in range(ss):
                    ray = rays[base + j]
                    dx = ray[0] * R[0, 0] + ray[1] * R[1, 0] + ray[2] * R[2, 0]
                    dy = ray[0] * R[0, 1] + ray[1] * R[1, 1] + ray[2] * R[2, 1]
                    dz = ray[0] * R[0, 2] + ray[1] * R[1, 2] + ray[2] * R[2, 2]
                    if dz == 0.0:
                        continue
                    t = -centre[2] / dz
                    if not t > 0.0:
                        continue
                    x = centre[0] + t * dx
                    y = centre[1] + t * dy
                    if x < x0 or x >= x1 or y < y0 or y >= y1:
                        continue
                    col = min(max(int((x - x0) * texels_per_m), 0), tw - 1)
                    row = min(max(int((y1 - y) * texels_per_m), 0), th - 1)
                    p_sum += texture[row, col]
                    n_on += 1
            paper[r, c] = p_sum * inv
            cover[r, c] = n_on * inv
    return paper, cover


def _design(u: np.ndarray, v: np.ndarray, degree: int) -> np.ndarray:
    return np.stack([u**i * v**j for i in range(degree + 1) for j in range(degree + 1 - i)], 1)


@functools.lru_cache(maxsize=2)
def _image_design(h: int, w: int, degree: int) -> np.ndarray:
    """The polynomial design over every pixel of an (h, w) image (evaluated for every frame
    and channel of every view: built once)."""
    gv, gu = np.mgrid[0:h, 0:w]
    full = _design(2 * (gu.ravel() + 0.5) / w - 1, 2 * (gv.ravel() + 0.5) / h - 1, degree)
    full.flags.writeable = False
    return full


def fit_shading(
    values: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    shape: tuple[int, int],
    degree: int = 3,
    iterations: int = 6,
) -> tuple[np.ndarray, float]:
    """Robust least-squares polynomial ``k(u, v)`` through ``values`` at clear-paper pixels
    -> (k over the whole image (H, W), relative residual spread of the inliers)."""
    h, w = shape
    design = _design(2 * (cols + 0.5) / w - 1, 2 * (rows + 0.5) / h - 1, degree)
    keep = np.ones(len(values), bool)
    spread = 1.0
    coef = np.zeros(design.shape[1])
    for _ in range(iterations):
        if keep.sum() < design.shape[1] * 4:
            break
        kept = design[keep]  # 10 smooth columns on [-1, 1]²: the normal equations are safe
        coef = np.linalg.solve(kept.T @ kept, kept.T @ values[keep])
        model = design @ coef
        rel = (values - model) / np.maximum(np.abs(model), 1e-9)
        spread = max(1.4826 * float(np.median(np.abs(rel[keep]))), 1e-4)
        keep = np.abs(rel) < max(3.0 * spread, 0.02)
    return (_image_design(h, w, degree) @ coef).reshape(h, w), spread


def _blur(image: np.ndarray, sigma: float) -> np.ndarray:
    return cv2.GaussianBlur(image.astype(np.float32), (0, 0), sigma)


def ground_deviation(
    images: list[np.ndarray],
    spec: BoardSpec,
    intrinsics: Intrinsics,
    pose: Pose,
    blur_px: float = 1.0,
) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
    """Per pixel, the RMS over channels and frames of how far the image departs from the
    printed board, in units of each channel's noise -> (deviation, on-board, clear paper);
    the deviation is None when too little clear paper is in view to fit the shading.

    Image and prediction get the same blur (fewer noise, same model since ``k`` is smooth),
    ``k`` comes from the clear-paper pixels and the ink/paper ratio from the ink pixels."""
    paper, cover = expected_ground(spec, intrinsics, pose)
    h, w = paper.shape
    if images[0].shape[:2] != (h, w):
        raise ValueError(f"image {images[0].shape[:2]} and camera {(h, w)} sizes differ")
    kernel3 = np.ones((3, 3), np.uint8)
    sure_cover = cv2.erode(cover, kernel3) > 0.999
    # the optics spill paper light a pixel or two beyond the sheet's edge
    on_board = cv2.dilate(cover, np.ones((5, 5), np.uint8)) > 0
    lit_paper = sure_cover & (cv2.erode(paper, kernel3) > 0.97)
    ink = sure_cover & (cv2.dilate(paper, kernel3) < 0.03)
    rows, cols = np.nonzero(lit_paper)
    sq_dev = np.zeros((h, w), np.float32)
    used = 0
    if len(rows) < MIN_PAPER_PX:
        return None, on_board, lit_paper
    for image in images:
        for c in range(image.shape[2]):
            channel = _blur(image[..., c], blur_px)
            k, _ = fit_shading(channel[rows, cols].astype(np.float64), rows, cols, (h, w))
            scale = float(np.median(k[lit_paper]))
            if not scale > 0:  # an unlit channel says nothing
                continue
            ratio = channel / np.maximum(k, 1e-3 * scale)
            eps = float(np.clip(np.median(ratio[ink]), 0.0, 0.5)) if ink.any() else 0.05
            expected = _blur(cover * (eps + (1 - eps) * paper), blur_px)
            residual = ratio - expected
            fit = residual[lit_paper | ink]
            noise = max(1.4826 * float(np.median(np.abs(fit - np.median(fit)))), 1e-4)
            # printed edges fit worse (demosaicing, pose error): the error grows with the
            # local contrast, at a rate measured on the edges themselves (mostly ground)
            contrast = cv2.dilate(expected, kernel3) - cv2.erode(expected, kernel3)
            edges = sure_cover & (contrast > 0.2)
            slope = (
                1.4826 * float(np.median(np.abs(residual[edges]) / contrast[edges]))
                if edges.any()
                else 0.0
            )
            sq_dev += residual**2 / (noise**2 + (slope * contrast) ** 2)
            used += 1
    return (np.sqrt(sq_dev / used) if used else None), on_board, lit_paper


def board_silhouette(
    images: list[np.ndarray],
    spec: BoardSpec,
    intrinsics: Intrinsics,
    pose: Pose,
    sigmas: float = 5.0,
    window_px: int = 3,
    close_px: int = 4,
    open_px: int = 1,
) -> np.ndarray:
    """Linear RGB images of one view (same pose) on the board -> bool object mask (H, W).

    A pixel is object when its deviation from the board (averaged over a ``window_px`` box)
    exceeds ``sigmas`` noise units; off the sheet, when it is brighter than the dark
    background's noise allows (or than 2 % of the paper)."""
    deviation, on_board, lit_paper = ground_deviation(images, spec, intrinsics, pose)
    if deviation is None:
        log.warning("too little of the board's paper in view: dark-background silhouette")
        return silhouette(images)
    obj = on_board & (cv2.blur(deviation, (window_px, window_px)) > sigmas)
    off = ~on_board
    if off.sum() > 100:
        brightness = np.sum([img.sum(axis=2) for img in images], axis=0)
        dark = brightness[off]
        spread = 1.4826 * float(np.median(np.abs(dark - np.median(dark))))
        level = float(np.median(dark)) + max(
            6 * spread, 0.02 * float(np.median(brightness[lit_paper]))
        )
        obj |= off & (brightness > level)
    # demosaicing and blur are unreliable on the outermost pixels: take the next ones in
    border = 2
    obj = np.pad(obj[border:-border, border:-border], border, mode="edge")
    mask: np.ndarray = obj.astype(np.uint8)
    for op, px in ((cv2.MORPH_CLOSE, close_px), (cv2.MORPH_OPEN, open_px)):
        if px:
            kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * px + 1,) * 2)
            mask = cv2.morphologyEx(mask, op, kernel)
    return fill_holes(mask > 0)
