"""PatchMatch multi-view stereo on the CPU: a depth and a normal per pixel of every view.

What COLMAP and OpenMVS do on the GPU (Bleyer et al. 2011; Galliani et al.'s Gipuma 2015;
Schönberger et al. 2016): each pixel holds a plane hypothesis (its distance along the pixel's
ray and a normal); red–black sweeps let every pixel try the planes of its neighbours
(propagation) and perturbations of its own (refinement), keeping whichever warps its window
into the neighbouring views with the best score (:mod:`plane_cost`, compiled).

The score is an NCC over the window samples of *all* illuminations of a view together, with
each one's plane of intensity (mean and linear ramp) removed: the lamp rides on the camera, so
the shading differs between views by much more than a gain, and a window's smooth shading slope
is no texture to match. Windows with no texture left (the interior of a uniformly painted
region) are not matched at all; Poisson fills them from the matched surroundings. A view's
cost is the mean of its ``top_k`` best source views, which tolerates occlusion in the others.

The visual hull only bounds the search (depths from just in front of its surface to
``depth_range`` behind it); it is never surface. Fused points are those confirmed by other
views' depth maps, averaged with the points that confirm them.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from core.config import bounded
from reconstruct.initial_mesh.dense.plane_cost import (
    INVALID_COST,
    evaluate,
    k_inverse,
    sweep,
    texture_map,
)
from reconstruct.model.camera import CAMERA_MODELS, Intrinsics, Pose
from reconstruct.model.raycast import RayCaster

log = logging.getLogger("reconstruct.initial_mesh.dense")
# one level below the frames: the level reconstruct.stages.resolution picks at 1-2 px edges
DEFAULT_SCALE = 0.5


@dataclass(frozen=True)
class PatchMatchConfig:
    """``scale``: image scale the depth maps are computed at, relative to the decoded frames
    (unset: from ``resolution``, one level below the optimiser's: 0.5 at edges of 1–2 px,
    :mod:`reconstruct.stages.resolution`); ``window`` samples per side,
    ``window_step`` pixels apart; ``sources``: neighbouring views matched against, of which the
    ``top_k`` best count; ``depth_range``: search depth behind the visual hull, as a fraction
    of the hull's largest extent; ``min_texture``: a window's RMS after its intensity planes are
    removed, relative to its mean level, below which it has nothing to match; ``cost_max``:
    1 - NCC above which a pixel is dropped; ``consistency_px`` / ``consistency_depth``: a point
    is confirmed by another view when that view's depth, read where the point projects, puts
    it back within this many pixels of its own pixel and this relative depth;
    ``min_consistent``: views that must confirm a point; ``mirror_deg``: pixels whose surface
    normal lies within this angle of the lamp's mirror direction are left out of a second
    fusion (:mod:`reconstruct.initial_mesh.dense.mirror`; 0: fuse once; unset: 20 when the
    optimiser is told the object is glossy and there are at least 24 views, else 0);
    ``bright_ratio``: pixels brighter than this many times what their point's albedo and
    normal, fitted to its brightness in the views that see it, predict are left out of that
    fusion too (:mod:`reconstruct.initial_mesh.dense.bright_pixels`; 0: none; unset: 1.2
    where ``mirror_deg`` is 20 by default, else 0; it needs the first surface, so it runs with
    a ``mirror_deg`` of 0 too);
    ``seed``: random hypotheses."""

    scale: float | None = bounded(None, above=0.0, max=1.0)
    window: int = bounded(5, min=1, max=63)
    window_step: int = bounded(1, min=1, max=16)
    sources: int = bounded(4, min=1, max=64)
    top_k: int = bounded(2, min=1, max=64)
    iterations: int = bounded(6, min=0, max=100)
    depth_range: float = bounded(0.15, above=0.0, max=10.0)
    # search in front of the hull too, as a fraction of depth_range
    hull_margin: float = bounded(0.5, min=0.0, max=10.0)
    cost_max: float = bounded(0.5, min=0.0, max=2.0)
    min_texture: float = bounded(0.02, min=0.0, max=10.0)
    consistency_px: float = bounded(0.5, min=0.0, max=1000.0)
    consistency_depth: float = bounded(0.005, min=0.0, max=1.0)
    min_consistent: int = bounded(2, min=1, max=64)
    mirror_deg: float | None = bounded(None, min=0.0, max=90.0)
    bright_ratio: float | None = bounded(None, min=0.0, max=100.0)
    # planes seen more obliquely than this are not proposed
    max_normal_deg: float = bounded(80.0, above=0.0, max=90.0)
    poisson_depth: int = bounded(9, min=1, max=14)
    poisson_trim: float = bounded(2.0, min=0.0, max=1000.0)
    seed: int = bounded(0, min=0)


@dataclass
class ViewDepth:
    """One view's result at the working scale: distance along each pixel's unit ray (NaN
    where unknown), camera-frame normals and 1 - NCC."""

    distance: np.ndarray  # (H, W)
    normal: np.ndarray  # (H, W, 3) camera frame
    cost: np.ndarray  # (H, W)
    intrinsics: Intrinsics  # at the working scale

    def depth(self, cost_max: float) -> np.ndarray:
        """Camera z of the pixels matched better than ``cost_max`` (NaN elsewhere)."""
        h, w = self.distance.shape
        z = self.distance * _rays_image(self.intrinsics, h, w)[..., 2]
        return np.where(self.cost < cost_max, z, np.nan)


@dataclass
class DenseResult:
    """Fused oriented points, counts, every view's depth map (what it saw as surface) and the
    views it was matched against and confirmed by."""

    points: np.ndarray
    normals: np.ndarray
    stats: dict[str, int]
    maps: dict[int, ViewDepth]
    sources: dict[int, list[int]]


def scaled(intr: Intrinsics, scale: float) -> Intrinsics:
    """The intrinsics of the image resized by ``scale`` (COLMAP's pixel-corner origin makes
    focal lengths and principal point scale exactly)."""
    width, height = round(intr.width * scale), round(intr.height * scale)
    sx, sy = width / intr.width, height / intr.height
    factor = {"f": sx, "fx": sx, "cx": sx, "fy": sy, "cy": sy}
    names = CAMERA_MODELS[intr.model]
    params = tuple(v * factor.get(n, 1.0) for n, v in zip(names, intr.params, strict=True))
    return Intrinsics(intr.model, width, height, params)


def source_views(poses: dict[int, Pose], centre: np.ndarray, k: int,
                 min_deg: float = 4.0, max_deg: float = 45.0) -> dict[int, list[int]]:
    """Per view the ``k`` views with the most useful parallax: looking at the object from
    directions between ``min_deg`` and ``max_deg`` away, nearest first."""
    views = sorted(poses)
    dirs = np.array([poses[v].center - centre for v in views])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(dirs @ dirs.T, -1, 1)))
    angle[(angle < min_deg) | (angle > max_deg)] = np.inf
    order = np.argsort(angle, axis=1)[:, :k]
    return {v: [views[j] for j in order[i] if np.isfinite(angle[i, j])]
            for i, v in enumerate(views)}


def window_offsets(conf: PatchMatchConfig) -> tuple[np.ndarray, np.ndarray]:
    """Row and column offsets (J,) of the window samples around a pixel."""
    half = conf.window // 2
    o = np.arange(-half, half + 1) * conf.window_step
    dr, dc = np.meshgrid(o, o, indexing="ij")
    return dr.ravel(), dc.ravel()


def _facing(normal: np.ndarray, rays: np.ndarray, max_deg: float) -> np.ndarray:
    """Normals flipped towards the camera and pulled inside the ``max_deg`` cone."""
    normal = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    dot = np.einsum("nk,nk->n", normal, rays)
    normal = np.where(dot[:, None] > 0, -normal, normal)
    cos_max = np.cos(np.radians(max_deg))
    too_oblique = -np.abs(dot) > -cos_max
    blended = normal - rays
    blended /= np.linalg.norm(blended, axis=1, keepdims=True)
    return np.where(too_oblique[:, None], blended, normal)


def patchmatch_view(
    ref: np.ndarray,
    mask: np.ndarray,
    intr: Intrinsics,
    pose: Pose,
    sources: list[tuple[np.ndarray, Intrinsics, Pose]],
    hull: RayCaster,
    span: float,
    conf: PatchMatchConfig,
) -> ViewDepth:
    """Depth and normal maps of one view (images already at the working scale, ``ref`` and
    sources (H, W, C) pinhole images of one size)."""
    h, w = mask.shape
    distance = np.full((h, w), np.nan)
    normal = np.zeros((h, w, 3))
    cost = np.full((h, w), INVALID_COST)
    reach = (conf.window // 2) * conf.window_step
    interior = np.zeros_like(mask)
    interior[reach:h - reach, reach:w - reach] = mask[reach:h - reach, reach:w - reach]
    dr, dc = window_offsets(conf)
    image = np.ascontiguousarray(ref, dtype=np.float32)
    texture = texture_map(image, interior, dr, dc)
    rows, cols = np.nonzero(interior & (texture >= conf.min_texture))
    rays_img = _rays_image(intr, h, w)
    rays = rays_img[rows, cols]
    tri, near, _ = hull.first_hit(np.broadcast_to(pose.center, rays.shape), rays @ pose.R)
    inside = np.isfinite(near)
    if inside.sum() < 16 or not sources:
        return ViewDepth(distance, normal, cost, intr)
    rows, cols, rays, near = rows[inside], cols[inside], rays[inside], near[inside]
    corners = hull.vertices[hull.faces[tri[inside]]]
    hull_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]) @ pose.R.T
    active = np.zeros((h, w), bool)
    active[rows, cols] = True
    # the hull is carved from silhouettes a voxel or two too tight in places: search a margin
    # in front of it as well
    lo = np.zeros((h, w))
    hi = np.zeros((h, w))
    lo[rows, cols] = near - conf.hull_margin * span
    hi[rows, cols] = near + span
    rng = np.random.default_rng(conf.seed)
    # start on the hull, facing as it does: convex parts are close already, and propagation
    # and random proposals reach into the concavities
    distance[rows, cols] = near + conf.hull_margin * span * rng.uniform(-1, 0.5, len(near))
    normal[rows, cols] = _facing(hull_normals, rays, conf.max_normal_deg)
    images = np.ascontiguousarray(np.stack([im for im, _, _ in sources]), dtype=np.float32)
    A = np.empty((len(sources), 3, 3))
    b = np.empty((len(sources), 3))
    for k, (_, s_intr, s_pose) in enumerate(sources):
        R = s_pose.R @ pose.R.T
        A[k] = s_intr.K @ R
        b[k] = s_intr.K @ (s_pose.t - R @ pose.t)
    K_inv = k_inverse(np.array([*intr.K[[0, 1], [0, 1]], *intr.K[:2, 2]]))
    cos_max = float(np.cos(np.radians(conf.max_normal_deg)))
    cost = evaluate(image, active, rays_img, distance, normal, dr, dc, K_inv, images, A, b,
                    conf.top_k)
    for it in range(conf.iterations):
        shrink = 0.5 ** (it + 1)
        for colour in (0, 1):
            noise = rng.uniform(-1.0, 1.0, (h, w, 9))
            sweep(colour, image, active, rays_img, lo, hi, distance, normal, cost, dr, dc,
                  K_inv, images, A, b, conf.top_k, noise, 0.25 * shrink, shrink, cos_max,
                  it < conf.iterations - 1)
        log.debug("iteration %d: median cost %.3f", it, float(np.median(cost[active])))
    distance[~active] = np.nan
    return ViewDepth(distance, normal, cost, intr)


def _rays_image(intr: Intrinsics, h: int, w: int) -> np.ndarray:
    rr, cc = np.mgrid[0:h, 0:w]
    uv = np.stack([cc.ravel() + 0.5, rr.ravel() + 0.5], 1)
    return intr.pixel_rays(uv).reshape(h, w, 3)


def fuse(
    maps: dict[int, ViewDepth],
    poses: dict[int, Pose],
    sources: dict[int, list[int]],
    conf: PatchMatchConfig,
) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """World points and normals of pixels whose depth other views confirm, each averaged with
    the points (and normals) of the views that confirm it."""
    points, normals = [], []
    total = 0
    for view, vd in maps.items():
        good = np.isfinite(vd.distance) & (vd.cost < conf.cost_max)
        rows, cols = np.nonzero(good)
        total += len(rows)
        if not len(rows):
            continue
        rays = vd.intrinsics.pixel_rays(np.stack([cols + 0.5, rows + 0.5], 1))
        world = poses[view].to_world(rays * vd.distance[rows, cols, None])
        n_world = vd.normal[rows, cols] @ poses[view].R
        votes = np.zeros(len(rows), np.int32)
        point_sum, normal_sum = world.copy(), n_world.copy()
        for other in sources[view]:
            if other not in maps:
                continue
            om = maps[other]
            x_o = poses[other].to_camera(world)
            uv = om.intrinsics.project_camera(x_o)
            inside = om.intrinsics.in_image(uv)
            col = np.clip(np.nan_to_num(uv[:, 0]).astype(int), 0, om.intrinsics.width - 1)
            row = np.clip(np.nan_to_num(uv[:, 1]).astype(int), 0, om.intrinsics.height - 1)
            # The other view's reading along the ray through the projection itself, not through
            # the nearest pixel's centre: the check then measures depth disagreement alone, not
            # where the point fell inside that pixel.
            d_o = depth_at(om.distance, uv)
            r_o = om.intrinsics.pixel_rays(np.nan_to_num(uv))
            back = poses[other].to_world(r_o * d_o[:, None])  # the other view's point
            reproj = project_point_error(back, poses[view], vd.intrinsics, rows, cols)
            dist = np.linalg.norm(x_o, axis=1)
            with np.errstate(invalid="ignore"):
                agree = (
                    inside
                    & (np.abs(d_o - dist) < conf.consistency_depth * dist)
                    & (reproj < conf.consistency_px)
                    & (om.cost[row, col] < conf.cost_max)
                )
            votes += agree
            point_sum[agree] += back[agree]
            normal_sum[agree] += om.normal[row[agree], col[agree]] @ poses[other].R
        keep = votes >= conf.min_consistent
        points.append(point_sum[keep] / (1.0 + votes[keep, None]))
        n = normal_sum[keep]
        normals.append(n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12))
    p = np.concatenate(points) if points else np.zeros((0, 3))
    n = np.concatenate(normals) if normals else np.zeros((0, 3))
    return p, n, {"patchmatch_pixels": total, "patchmatch_points": len(p)}


def depth_at(distance: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """A depth map's bilinear reading at pixel coordinates ``uv`` (M, 2), over its finite taps
    only (NaN where none is): a pixel beside a hole or a dropped pixel still reads its own depth.

    >>> depth_at(np.array([[1.0, 3.0], [np.nan, 5.0]]), np.array([[1.0, 0.5], [1.0, 1.0]])).tolist()
    [2.0, 3.0]
    """
    # normalised convolution: the bilinear weights of the finite taps alone
    coords = [np.nan_to_num(uv[:, 1]) - 0.5, np.nan_to_num(uv[:, 0]) - 0.5]
    finite = np.isfinite(distance)
    total = map_coordinates(np.where(finite, distance, 0.0), coords, order=1, mode="nearest")
    weight = map_coordinates(finite.astype(float), coords, order=1, mode="nearest")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weight > 0, total / weight, np.nan)


def project_point_error(
    points: np.ndarray, pose: Pose, intr: Intrinsics, rows: np.ndarray, cols: np.ndarray
) -> np.ndarray:
    """Pixel distance between ``points`` projected into a view and the pixels they came from."""
    uv = intr.project_camera(pose.to_camera(points))
    return np.hypot(uv[:, 0] - (cols + 0.5), uv[:, 1] - (rows + 0.5))


def patchmatch_points(
    hull_vertices: np.ndarray,
    hull_faces: np.ndarray,
    images: dict[int, np.ndarray],
    masks: dict[int, np.ndarray],
    intrinsics: dict[int, Intrinsics],
    poses: dict[int, Pose],
    conf: PatchMatchConfig,
    progress: Callable[[int, int], None] | None = None,
) -> DenseResult:
    """Oriented points of the object from per-view PatchMatch depth maps, bounded by the
    visual hull (``hull_vertices``/``hull_faces``); ``images`` are (H, W, C) per view at
    full size."""
    caster = RayCaster(hull_vertices, hull_faces)
    span = conf.depth_range * float(np.ptp(hull_vertices, axis=0).max())
    views = sorted(v for v in masks if v in poses)
    srcs = source_views({v: poses[v] for v in views}, hull_vertices.mean(0), conf.sources)
    small, small_masks, intr_s = working_images(images, masks, intrinsics, views, conf)
    maps: dict[int, ViewDepth] = {}
    for i, v in enumerate(views):
        sources = [(small[o], intr_s[o], poses[o]) for o in srcs[v]]
        maps[v] = patchmatch_view(small[v], small_masks[v], intr_s[v], poses[v], sources,
                                  caster, span, conf)
        if progress is not None:
            progress(i + 1, len(views))
    points, normals, stats = fuse(maps, poses, srcs, conf)
    return DenseResult(points, normals, stats, maps, srcs)


def working_images(
    images: dict[int, np.ndarray],
    masks: dict[int, np.ndarray],
    intrinsics: dict[int, Intrinsics],
    views: list[int],
    conf: PatchMatchConfig,
) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], dict[int, Intrinsics]]:
    """The ``views``' images (H, W, C), masks and pinhole intrinsics as PatchMatch matches
    them: undistorted and resized to the working scale."""
    pinhole = {v: undistorted(images[v], masks[v], intrinsics[v]) for v in views}
    scale = DEFAULT_SCALE if conf.scale is None else conf.scale
    small = {v: _resize(pinhole[v][0], scale) for v in views}
    small_masks = {v: _resize(pinhole[v][1].astype(np.float32), scale) > 0.5 for v in views}
    return small, small_masks, {v: scaled(pinhole[v][2], scale) for v in views}


def undistorted(
    image: np.ndarray, mask: np.ndarray, intr: Intrinsics
) -> tuple[np.ndarray, np.ndarray, Intrinsics]:
    """The image (H, W, I) and mask as a pinhole camera with the same K would see them (the
    matching kernel projects with K alone, as COLMAP's PatchMatch works on undistorted
    images)."""
    K = intr.K
    pinhole = Intrinsics("PINHOLE", intr.width, intr.height, (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
    if not intr.distortion().any():
        return image, mask, pinhole
    K_cv = K.copy()
    K_cv[:2, 2] -= 0.5  # OpenCV puts the top-left pixel's centre at 0, COLMAP at 0.5
    map_x, map_y = cv2.initUndistortRectifyMap(
        K_cv, intr.distortion(), None, K_cv, (intr.width, intr.height), cv2.CV_32FC1
    )
    channels = [cv2.remap(image[..., i].astype(np.float32), map_x, map_y, cv2.INTER_LINEAR)
                for i in range(image.shape[2])]
    warped_mask = cv2.remap(mask.astype(np.uint8), map_x, map_y, cv2.INTER_NEAREST) > 0
    return np.stack(channels, axis=-1), warped_mask, pinhole


def _resize(image: np.ndarray, scale: float) -> np.ndarray:
    if scale == 1.0:
        return image.astype(np.float32)
    h, w = image.shape[:2]
    size = (round(w * scale), round(h * scale))
    out = cv2.resize(image.astype(np.float32), size, interpolation=cv2.INTER_AREA)
    return out.reshape(size[1], size[0], *image.shape[2:])
