"""PatchMatch multi-view stereo on the CPU: a depth and a normal per pixel of every view.

What COLMAP and OpenMVS do on the GPU (Bleyer et al. 2011; Schönberger et al. 2016; Xu & Tao's
ACMH), vectorised over all pixels of a view at once: each pixel holds a plane hypothesis (its
distance along the pixel's ray and a normal); every iteration each pixel tries the planes of its
neighbours (propagation) and random perturbations of its own (refinement), keeping whichever
warps its window into the neighbouring views with the best score.

The score is a zero-mean NCC computed over the window samples of *all* illuminations of a view
together: the lamp rides on the camera, so the shading differs between views by much more than
a gain — centring and normalising per illumination removes each frame's local gain and offset,
while stacking them gives the match several independent textures (a colour edge that one lamp
hides, another shows). A view's cost is the mean of its ``top_k`` best source views, which
tolerates occlusion in the others.

The visual hull only bounds the search (depths from its surface to ``depth_range`` behind it);
it is never surface. Fused points are those confirmed by other views' depth maps.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from reconstruct.camera import CAMERA_MODELS, Intrinsics, Pose
from reconstruct.dense.plane_cost import INVALID_COST, plane_costs
from reconstruct.raycast import RayCaster

log = logging.getLogger("reconstruct.dense")



@dataclass(frozen=True)
class PatchMatchConfig:
    """``scale``: image scale the depth maps are computed at; ``window`` samples per side,
    ``window_step`` pixels apart; ``sources``: neighbouring views matched against, of which the
    ``top_k`` best count; ``depth_range``: search depth behind the visual hull, as a fraction
    of the hull's largest extent; ``cost_max``: 1 - NCC above which a pixel is dropped;
    ``consistency_px`` / ``consistency_depth``: a point is confirmed by another view when it
    reprojects into that view's depth map within this many pixels and relative depth;
    ``min_consistent``: views that must confirm a point; ``seed``: random hypotheses."""

    scale: float = 0.5
    window: int = 5
    window_step: int = 2
    sources: int = 6
    top_k: int = 3
    iterations: int = 6
    depth_range: float = 0.15
    hull_margin: float = 0.5  # search in front of the hull too, as a fraction of depth_range
    cost_max: float = 0.5
    min_texture: float = 1e-3  # relative window std below which a pixel has nothing to match
    consistency_px: float = 1.0
    consistency_depth: float = 0.005
    min_consistent: int = 2
    max_normal_deg: float = 80.0  # planes seen more obliquely than this are not proposed
    poisson_depth: int = 9
    poisson_trim: float = 5.0
    seed: int = 0


@dataclass
class ViewDepth:
    """One view's result at the working scale: distance along each pixel's unit ray (NaN
    where unknown), camera-frame normals and 1 - NCC."""

    distance: np.ndarray  # (H, W)
    normal: np.ndarray  # (H, W, 3) camera frame
    cost: np.ndarray  # (H, W)
    intrinsics: Intrinsics  # at the working scale


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


class _Matcher:
    """Scores plane hypotheses of one reference view's pixels against its sources (pinhole
    cameras, images (H, W, I) of one size)."""

    def __init__(
        self,
        ref: np.ndarray,
        rows: np.ndarray,
        cols: np.ndarray,
        intr: Intrinsics,
        pose: Pose,
        sources: list[tuple[np.ndarray, Intrinsics, Pose]],
        conf: PatchMatchConfig,
    ) -> None:
        self.conf = conf
        offsets = window_offsets(conf)
        self.dv, self.du = (o.astype(np.float64) for o in offsets)
        self.u, self.v = cols + 0.5, rows + 0.5
        self.rays = intr.pixel_rays(np.stack([self.u, self.v], 1))
        patch = ref[rows[:, None] + offsets[0], cols[:, None] + offsets[1]].astype(np.float32)
        self.ref, self.texture = _normalise(patch, conf.min_texture)
        K = intr.K
        self.inv = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
        self.images = np.stack([image for image, _, _ in sources]).astype(np.float32)
        self.A = np.empty((len(sources), 3, 3))
        self.b = np.empty((len(sources), 3))
        for s, (_, s_intr, s_pose) in enumerate(sources):
            R = s_pose.R @ pose.R.T
            self.A[s] = s_intr.K @ R
            self.b[s] = s_intr.K @ (s_pose.t - R @ pose.t)

    def cost(self, idx: np.ndarray, distance: np.ndarray, normal: np.ndarray) -> np.ndarray:
        """1 - NCC (mean of the ``top_k`` best sources) of the planes through pixels ``idx``'s
        points at ``distance`` along their rays with camera-frame ``normal``."""
        costs = plane_costs(
            self.u[idx], self.v[idx], self.rays[idx], np.ascontiguousarray(distance, float),
            np.ascontiguousarray(normal, float), self.ref[idx], self.du, self.dv, self.inv,
            self.images, self.A, self.b, self.conf.top_k, self.conf.min_texture,
        )
        return np.where(self.texture[idx], costs, INVALID_COST)


def window_offsets(conf: PatchMatchConfig) -> tuple[np.ndarray, np.ndarray]:
    """Row and column offsets (J,) of the window samples around a pixel."""
    half = conf.window // 2
    o = np.arange(-half, half + 1) * conf.window_step
    dr, dc = np.meshgrid(o, o, indexing="ij")
    return dr.ravel(), dc.ravel()


def _normalise(patch: np.ndarray, min_texture: float) -> tuple[np.ndarray, np.ndarray]:
    """Windows (N, J, I) centred per illumination and scaled to unit norm over all samples;
    and which windows have texture (std above ``min_texture`` of their mean)."""
    mean = patch.mean(axis=1, keepdims=True)
    centred = patch - mean
    norm = np.sqrt(np.einsum("nji,nji->n", centred, centred))
    level = np.abs(mean).mean(axis=(1, 2)) * np.sqrt(patch.shape[1] * patch.shape[2])
    texture = norm > min_texture * np.maximum(level, 1e-12)
    return centred / np.maximum(norm, 1e-12)[:, None, None], texture


def _random_normals(rng: np.random.Generator, rays: np.ndarray, max_deg: float) -> np.ndarray:
    """Random unit normals facing the camera within ``max_deg`` of the viewing ray."""
    n = rng.normal(size=rays.shape)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return _facing(n - 1.5 * rays, rays, max_deg)


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


def _shift(field: np.ndarray, dr: int, dc: int, fill: float) -> np.ndarray:
    """``field`` moved so that each pixel sees its neighbour at (+dr, +dc)."""
    out = np.full_like(field, fill)
    h, w = field.shape[:2]
    dst_r = slice(max(-dr, 0), h - max(dr, 0))
    src_r = slice(max(dr, 0), h - max(-dr, 0))
    dst_c = slice(max(-dc, 0), w - max(dc, 0))
    src_c = slice(max(dc, 0), w - max(-dc, 0))
    out[dst_r, dst_c] = field[src_r, src_c]
    return out


# near and far neighbours (as Gipuma's pattern): each iteration tries the best of each group
NEIGHBOUR_GROUPS = (((0, 1), (0, -1), (1, 0), (-1, 0)), ((0, 5), (0, -5), (5, 0), (-5, 0)),
                    ((3, 3), (3, -3), (-3, 3), (-3, -3)))


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
    sources (H, W, I) grey per illumination)."""
    h, w = mask.shape
    distance = np.full((h, w), np.nan)
    normal = np.zeros((h, w, 3))
    cost = np.full((h, w), INVALID_COST)
    reach = (conf.window // 2) * conf.window_step
    interior = np.zeros_like(mask)
    interior[reach:h - reach, reach:w - reach] = mask[reach:h - reach, reach:w - reach]
    rows, cols = np.nonzero(interior)
    rays = intr.pixel_rays(np.stack([cols + 0.5, rows + 0.5], 1))
    centre = np.broadcast_to(pose.center, rays.shape)
    tri, near, _ = hull.first_hit(centre, rays @ pose.R)
    inside = np.isfinite(near)
    if inside.sum() < 16 or not sources:
        return ViewDepth(distance, normal, cost, intr)
    rows, cols, rays, near = rows[inside], cols[inside], rays[inside], near[inside]
    corners = hull.vertices[hull.faces[tri[inside]]]
    hull_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]) @ pose.R.T
    # the hull is carved from silhouettes a voxel or two too tight in places: search a margin
    # in front of it as well
    lo, hi = near - conf.hull_margin * span, near + span
    matcher = _Matcher(ref, rows, cols, intr, pose, sources, conf)
    rng = np.random.default_rng(conf.seed)

    everyone = np.arange(len(near))
    # start on the hull, facing as it does: convex parts are close already, and propagation
    # and random proposals reach into the concavities
    d = near + conf.hull_margin * span * rng.uniform(-1, 0.5, len(near))
    n = _facing(hull_normals, rays, conf.max_normal_deg)
    c = matcher.cost(everyone, d, n)

    def keep_better(idx: np.ndarray, d_new: np.ndarray, n_new: np.ndarray) -> None:
        ok = (d_new >= lo[idx]) & (d_new <= hi[idx])
        idx, d_new, n_new = idx[ok], d_new[ok], n_new[ok]
        if not len(idx):
            return
        c_new = matcher.cost(idx, d_new, n_new)
        better = c_new < c[idx]
        sel = idx[better]
        d[sel], n[sel], c[sel] = d_new[better], n_new[better], c_new[better]

    pixel_rays = _rays_image(intr, h, w)
    for it in range(conf.iterations):
        distance[rows, cols], normal[rows, cols], cost[rows, cols] = d, n, c
        rho_full = distance * np.einsum("hwk,hwk->hw", normal, pixel_rays)
        for group in NEIGHBOUR_GROUPS:  # propagate the best plane of each group of neighbours
            c_nb = np.stack([_shift(cost, dr, dc, INVALID_COST)[rows, cols] for dr, dc in group])
            pick = np.argmin(c_nb, axis=0)
            idx = np.flatnonzero(c_nb[pick, np.arange(len(c))] < c - 1e-4)
            if not len(idx):
                continue
            n_nb = np.empty((len(idx), 3))
            rho_nb = np.empty(len(idx))
            for g, (dr, dc) in enumerate(group):
                sel = pick[idx] == g
                n_nb[sel] = _shift(normal, dr, dc, 0.0)[rows[idx[sel]], cols[idx[sel]]]
                rho_nb[sel] = _shift(rho_full, dr, dc, np.nan)[rows[idx[sel]], cols[idx[sel]]]
            with np.errstate(divide="ignore", invalid="ignore"):  # that plane cut by this ray
                d_nb = rho_nb / np.einsum("nk,nk->n", n_nb, rays[idx])
            fine = np.isfinite(d_nb)
            keep_better(idx[fine], d_nb[fine],
                        _facing(n_nb[fine], rays[idx[fine]], conf.max_normal_deg))
        # refine: perturb depth and normal, shrinking the perturbation each iteration
        shrink = 0.5 ** (it + 1)
        d_try = d + span * 0.25 * shrink * rng.uniform(-1, 1, len(d))
        n_try = _facing(n + shrink * rng.normal(size=n.shape), rays, conf.max_normal_deg)
        keep_better(everyone, d_try, n_try)
        keep_better(everyone, d.copy(), n_try)
        keep_better(everyone, d_try, n.copy())
        keep_better(everyone, lo + (hi - lo) * rng.uniform(0, 1, len(d)),
                    _random_normals(rng, rays, conf.max_normal_deg))
        log.debug("iteration %d: median cost %.3f", it, float(np.median(c)))
    distance[:] = np.nan
    distance[rows, cols], normal[rows, cols], cost[rows, cols] = d, n, c
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
    """World points and normals of pixels whose depth other views confirm."""
    points, normals = [], []
    total = 0
    for view, vd in maps.items():
        h, w = vd.distance.shape
        good = np.isfinite(vd.distance) & (vd.cost < conf.cost_max)
        rows, cols = np.nonzero(good)
        total += len(rows)
        if not len(rows):
            continue
        rays = vd.intrinsics.pixel_rays(np.stack([cols + 0.5, rows + 0.5], 1))
        x_cam = rays * vd.distance[rows, cols, None]
        world = poses[view].to_world(x_cam)
        n_world = vd.normal[rows, cols] @ poses[view].R
        votes = np.zeros(len(rows), np.int32)
        for other in sources[view]:
            if other not in maps:
                continue
            om = maps[other]
            x_o = poses[other].to_camera(world)
            uv = om.intrinsics.project_camera(x_o)
            inside = om.intrinsics.in_image(uv)
            col = np.clip(np.nan_to_num(uv[:, 0]).astype(int), 0, om.intrinsics.width - 1)
            row = np.clip(np.nan_to_num(uv[:, 1]).astype(int), 0, om.intrinsics.height - 1)
            d_o = om.distance[row, col]
            r_o = om.intrinsics.pixel_rays(np.stack([col + 0.5, row + 0.5], 1))
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
        keep = votes >= conf.min_consistent
        points.append(world[keep])
        normals.append(n_world[keep])
    p = np.concatenate(points) if points else np.zeros((0, 3))
    n = np.concatenate(normals) if normals else np.zeros((0, 3))
    return p, n, {"patchmatch_pixels": total, "patchmatch_points": len(p)}


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
) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """Oriented points of the object from per-view PatchMatch depth maps, bounded by the
    visual hull (``hull_vertices``/``hull_faces``); ``images`` are (H, W, I) grey per
    illumination at full size."""
    caster = RayCaster(hull_vertices, hull_faces)
    span = conf.depth_range * float(np.ptp(hull_vertices, axis=0).max())
    views = sorted(v for v in masks if v in poses)
    srcs = source_views({v: poses[v] for v in views}, hull_vertices.mean(0), conf.sources)
    pinhole = {v: undistorted(images[v], masks[v], intrinsics[v]) for v in views}
    small = {v: _resize(pinhole[v][0], conf.scale) for v in views}
    small_masks = {v: _resize(pinhole[v][1].astype(np.float32), conf.scale) > 0.5 for v in views}
    intr_s = {v: scaled(pinhole[v][2], conf.scale) for v in views}
    maps: dict[int, ViewDepth] = {}
    for i, v in enumerate(views):
        sources = [(small[o], intr_s[o], poses[o]) for o in srcs[v]]
        maps[v] = patchmatch_view(small[v], small_masks[v], intr_s[v], poses[v], sources,
                                  caster, span, conf)
        if progress is not None:
            progress(i + 1, len(views))
    return fuse(maps, poses, srcs, conf)


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
