"""Hull-guided plane-sweep stereo (NCC) on the CPU: recovers what silhouettes cannot see.

The visual hull encloses the object, so along each pixel's ray the surface lies at or just
behind the hull. For every reference view the sweep tries depths from the hull inwards,
warps its neighbour views there and scores normalised cross-correlation over a small window
(invariant to the gain and offset changes a lamp moving with the camera causes). Pixels with
a clear, consistent best depth give oriented points; hull points that a confident depth map
shows to float in front of the surface are dropped (concavities). Both go to Poisson.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np
import trimesh
from scipy.ndimage import map_coordinates

from core.config import bounded
from reconstruct.model.camera import Intrinsics, Pose, project
from reconstruct.model.raycast import RayCaster
from reconstruct.stages.progress import track

log = logging.getLogger("reconstruct.initial_mesh.dense")


@dataclass(frozen=True)
class StereoConfig:
    neighbours: int = bounded(4, min=1, max=64)
    window: int = bounded(7, min=1, max=63)
    ncc_min: float = bounded(0.6, min=-1.0, max=1.0)
    # best NCC must beat any other peak (beyond ±3 steps) by this
    uniqueness: float = bounded(0.05, min=0.0, max=2.0)
    # of the hull's largest extent, swept inwards from the hull
    depth_range: float = bounded(0.15, above=0.0, max=10.0)
    max_steps: int = bounded(48, min=1, max=10_000)
    min_angle_deg: float = bounded(4.0, min=0.0, max=90.0)
    consistency: float = bounded(0.01, min=0.0, max=1.0)  # relative depth agreement between views
    min_consistent: int = bounded(2, min=1, max=64)  # views whose depth maps must confirm a point


@dataclass
class DepthMap:
    depth: np.ndarray  # (H, W) camera z, NaN where unknown
    points: np.ndarray  # (N, 3) world points of valid pixels
    normals: np.ndarray  # (N, 3)
    pixels: np.ndarray  # (N,) flat pixel index of each point

    def confirmed(self, ok: np.ndarray) -> np.ndarray:
        """The depth map with only the pixels whose points ``ok`` marks."""
        depth = np.full(self.depth.shape, np.nan)
        depth.flat[self.pixels[ok]] = self.depth.flat[self.pixels[ok]]
        return depth


def neighbours(
    poses: dict[int, Pose], centre: np.ndarray, k: int, min_deg: float
) -> dict[int, list[int]]:
    """For each view, the ``k`` views seeing the object from the nearest directions (but not
    from almost the same direction, which gives no parallax)."""
    views = sorted(poses)
    dirs = np.array([poses[v].center - centre for v in views])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(dirs @ dirs.T, -1, 1)))
    angle[angle < min_deg] = np.inf
    order = np.argsort(angle, axis=1)[:, :k]
    return {
        v: [views[j] for j in order[i] if np.isfinite(angle[i, j])] for i, v in enumerate(views)
    }


def _ncc(ref: np.ndarray, warped: np.ndarray, valid: np.ndarray, win: int) -> np.ndarray:
    k = (win, win)
    mu_r, mu_w = cv2.blur(ref, k), cv2.blur(warped, k)
    var_r = cv2.blur(ref * ref, k) - mu_r**2
    var_w = cv2.blur(warped * warped, k) - mu_w**2
    cov = cv2.blur(ref * warped, k) - mu_r * mu_w
    ncc = cov / np.sqrt(np.maximum(var_r * var_w, 1e-12))
    ok = cv2.blur(valid.astype(np.float32), k) > 0.999
    return np.where(ok & (var_r > 1e-8) & (var_w > 1e-8), ncc, -1.0)


def sweep_view(
    view: int,
    images: dict[int, np.ndarray],
    masks: dict[int, np.ndarray],
    intrinsics: dict[int, Intrinsics],
    poses: dict[int, Pose],
    near: list[int],
    hull: RayCaster,
    span: float,
    conf: StereoConfig,
) -> DepthMap:
    """Best NCC depth behind the hull for every silhouette pixel of ``view``."""
    intr, pose, mask = intrinsics[view], poses[view], masks[view]
    h, w = mask.shape
    rows, cols = np.nonzero(mask)
    r0, r1 = max(rows.min() - conf.window, 0), min(rows.max() + conf.window + 1, h)
    c0, c1 = max(cols.min() - conf.window, 0), min(cols.max() + conf.window + 1, w)
    rr, cc = np.mgrid[r0:r1, c0:c1]
    uv = np.stack([cc.ravel() + 0.5, rr.ravel() + 0.5], axis=1)
    dirs = intr.pixel_rays(uv) @ pose.R
    _, t_hull, _ = hull.first_hit(np.broadcast_to(pose.center, dirs.shape), dirs)
    hit = np.isfinite(t_hull)
    if not hit.any():  # the hull is not in this view: nothing to match
        empty = np.zeros((0, 3))
        return DepthMap(np.full((h, w), np.nan), empty, empty, np.zeros(0, np.int64))
    step = float(np.median(t_hull[hit])) / intr.K[0, 0]  # about one pixel of depth
    steps = int(min(conf.max_steps, max(4, np.ceil(span / step))))
    offsets = np.linspace(-2 * step, span, steps)
    ref = images[view][r0:r1, c0:c1]
    shape = ref.shape
    scores = np.full((steps, *shape), -1.0, np.float32)
    t0 = np.where(hit, t_hull, 0.0)
    # Along a ray x = c + t d, so in a neighbour's camera frame x' = (R c + t_o) + t (R d):
    # one product per neighbour instead of one per depth step.
    in_other = {
        o: (poses[o].to_camera(pose.center[None])[0], dirs @ poses[o].R.T) for o in near
    }
    for s, off in enumerate(offsets):
        depth_along = (t0 + off)[:, None]
        per_view = []
        for other in near:
            origin, direction = in_other[other]
            p = intrinsics[other].project_camera(origin + depth_along * direction)
            inside = intrinsics[other].in_image(p, 1.0) & hit
            coords = np.stack([p[:, 1] - 0.5, p[:, 0] - 0.5])
            coords = np.nan_to_num(coords, nan=-10.0)
            warped = map_coordinates(images[other], coords, order=1, cval=0.0)
            ok = inside & (map_coordinates(masks[other].astype(np.float32), coords, order=0) > 0)
            per_view.append(_ncc(ref, warped.reshape(shape).astype(np.float32),
                                 ok.reshape(shape), conf.window))
        stack = np.sort(np.array(per_view), axis=0)
        scores[s] = stack[-2:].mean(axis=0) if len(per_view) > 1 else stack[-1]
    best = np.argmax(scores, axis=0)
    score = np.take_along_axis(scores, best[None], 0)[0]
    # repetitive texture matches at several depths: insist on one clear winner
    far = np.abs(np.arange(steps)[:, None, None] - best[None]) > 3
    second = np.where(far, scores, -1.0).max(axis=0)
    # sub-step refinement with a parabola through the best score and its neighbours
    b = np.clip(best, 1, steps - 2)
    s_m, s_0, s_p = (np.take_along_axis(scores, (b + d)[None], 0)[0] for d in (-1, 0, 1))
    denom = s_m - 2 * s_0 + s_p
    frac = np.where(denom < -1e-6, 0.5 * (s_m - s_p) / np.where(denom < -1e-6, denom, 1), 0.0)
    frac = np.clip(np.where(best == b, frac, 0.0), -0.5, 0.5)
    offset = np.interp(best + frac, np.arange(steps), offsets)
    good = (score > conf.ncc_min) & (score - second > conf.uniqueness) & (best < steps - 1)
    good &= mask[r0:r1, c0:c1] & hit.reshape(shape)
    t = (t0.reshape(shape) + offset)
    pts = pose.center + t[..., None] * dirs.reshape(*shape, 3)
    depth = np.full((h, w), np.nan)
    z = pose.to_camera(pts.reshape(-1, 3))[:, 2].reshape(shape)
    depth[r0:r1, c0:c1] = np.where(good, z, np.nan)
    normals = _normals(pts, good, pose.center)
    keep = good & np.isfinite(normals).all(axis=-1)
    pixels = np.ravel_multi_index((rr[keep], cc[keep]), (h, w))
    return DepthMap(depth, pts[keep], normals[keep], pixels)


def _normals(points: np.ndarray, good: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Normals from central differences of the point map, facing the camera."""
    p = np.where(good[..., None], points, np.nan)
    du = np.zeros_like(p) * np.nan
    dv = np.zeros_like(p) * np.nan
    du[:, 1:-1] = p[:, 2:] - p[:, :-2]
    dv[1:-1] = p[2:] - p[:-2]
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    flip = np.einsum("...k,...k->...", n, centre - points) < 0
    return np.where(flip[..., None], -n, n)


def consistent(
    maps: dict[int, DepthMap],
    intrinsics: dict[int, Intrinsics],
    poses: dict[int, Pose],
    near: dict[int, list[int]],
    tol: float,
) -> dict[int, np.ndarray]:
    """Per view, how many other views' depth maps confirm each of its points."""
    out = {}
    for view, dm in maps.items():
        agree = np.zeros(len(dm.points), np.int32)
        for other in (o for o in near[view] if o in maps):
            z = poses[other].to_camera(dm.points)[:, 2]
            uv = project(intrinsics[other], poses[other], dm.points)
            inside = intrinsics[other].in_image(uv)
            col = np.clip(np.nan_to_num(uv[:, 0]).astype(int), 0, intrinsics[other].width - 1)
            row = np.clip(np.nan_to_num(uv[:, 1]).astype(int), 0, intrinsics[other].height - 1)
            zo = maps[other].depth[row, col]
            with np.errstate(invalid="ignore"):
                agree += inside & (np.abs(zo - z) < tol * z)
        out[view] = agree
    return out


def carve_hull_points(
    points: np.ndarray,
    depths: dict[int, np.ndarray],
    intrinsics: dict[int, Intrinsics],
    poses: dict[int, Pose],
    margin: float,
) -> np.ndarray:
    """Keep hull points no confirmed depth map puts in front of the surface by > margin."""
    keep = np.ones(len(points), bool)
    for view, depth in depths.items():
        uv = project(intrinsics[view], poses[view], points)
        inside = intrinsics[view].in_image(uv)
        col = np.clip(np.nan_to_num(uv[:, 0]).astype(int), 0, intrinsics[view].width - 1)
        row = np.clip(np.nan_to_num(uv[:, 1]).astype(int), 0, intrinsics[view].height - 1)
        z = poses[view].to_camera(points)[:, 2]
        with np.errstate(invalid="ignore"):
            keep &= ~(inside & (z < depth[row, col] - margin))
    return keep


def thin(points: np.ndarray, normals: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """One averaged oriented point per ``cell``-sized voxel (Poisson needs no more)."""
    keys = np.floor(points / cell).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    p = np.stack([np.bincount(inverse, points[:, k]) for k in range(3)], 1) / counts[:, None]
    n = np.stack([np.bincount(inverse, normals[:, k]) for k in range(3)], 1)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    ok = norm[:, 0] > 1e-9
    return p[ok], n[ok] / norm[ok]


def hull_stereo_points(
    hull_mesh: trimesh.Trimesh,
    hull_points: np.ndarray,
    hull_normals: np.ndarray,
    images: dict[int, np.ndarray],
    masks: dict[int, np.ndarray],
    intrinsics: dict[int, Intrinsics],
    poses: dict[int, Pose],
    voxel: float,
    conf: StereoConfig,
    floor: float | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """Oriented points: consistent stereo points plus the hull points stereo does not refute.
    With a ``floor`` (board at z = 0) stereo points on or under the board are dropped: the
    masks include the object's shadow, where the sweep finds the board itself."""
    caster = RayCaster(hull_mesh.vertices, hull_mesh.faces)
    span = conf.depth_range * float(np.ptp(hull_mesh.vertices, axis=0).max())
    posed = {v: poses[v] for v in masks}
    near = neighbours(posed, hull_mesh.vertices.mean(0), conf.neighbours, conf.min_angle_deg)
    views = [v for v in sorted(near) if near[v]]
    near = {v: [o for o in near[v] if o in views] for v in views}
    views = [v for v in views if near[v]]
    maps = {
        v: sweep_view(v, images, masks, intrinsics, poses, near[v], caster, span, conf)
        for v in track(views, "initial mesh: plane-sweep stereo")
    }
    votes = consistent(maps, intrinsics, poses, near, conf.consistency)
    ok = {v: votes[v] >= conf.min_consistent for v in views}
    sp = np.concatenate([maps[v].points[ok[v]] for v in views])
    sn = np.concatenate([maps[v].normals[ok[v]] for v in views])
    if floor is not None:
        above = sp[:, 2] > floor + voxel / 2
        sp, sn = sp[above], sn[above]
    # a hull point goes when one other view backs the deeper surface: dropping is cheap to
    # undo (Poisson closes small gaps), keeping a bridged concavity is not
    confirmed = {v: maps[v].confirmed(votes[v] >= 1) for v in views}
    keep = carve_hull_points(hull_points, confirmed, intrinsics, poses, 2 * voxel)
    stats = {"stereo_points": int(len(sp)), "hull_points_kept": int(keep.sum()),
             "hull_points_dropped": int((~keep).sum())}
    log.info("stereo: %(stereo_points)d consistent points, hull points kept "
             "%(hull_points_kept)d, dropped %(hull_points_dropped)d", stats)
    p, n = thin(np.concatenate([sp, hull_points[keep]]),
                np.concatenate([sn, hull_normals[keep]]), voxel / 2)
    return p, n, stats
