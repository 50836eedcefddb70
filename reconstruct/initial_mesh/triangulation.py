"""Multi-view triangulation of projector-block correspondences: which camera pixels see the
same projector block (block centroids matched across views), a vectorised multi-view DLT, and
the rejection of points by cheirality, reprojection error and triangulation angle."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reconstruct.initial_mesh.structured_light import GrayDecoding
from reconstruct.model.camera import Intrinsics, Pose, project


@dataclass(frozen=True)
class Observer:
    """A camera or a projector placement that observes projector blocks."""

    intrinsics: Intrinsics
    pose: Pose
    tolerance_px: float  # accepted reprojection error in this observer's pixels


def triangulate(obs: np.ndarray, observers: list[Observer]) -> np.ndarray:
    """Linear multi-view DLT, vectorised: pixels (N, V, 2) with NaN where unseen -> (N, 3).

    Rows are built in undistorted normalised coordinates, so distortion is handled and the
    system is well conditioned; unseen views contribute zero rows.
    """
    n, v, _ = obs.shape
    A = np.zeros((n, 2 * v, 4))
    for k, ob in enumerate(observers):
        seen = ~np.isnan(obs[:, k, 0])
        rays = ob.intrinsics.pixel_rays(obs[seen, k])
        xy = rays[:, :2] / rays[:, 2:3]
        P = np.hstack([ob.pose.R, ob.pose.t[:, None]])
        A[seen, 2 * k] = xy[:, :1] * P[2] - P[0]
        A[seen, 2 * k + 1] = xy[:, 1:2] * P[2] - P[1]
    A /= np.linalg.norm(A, axis=2, keepdims=True).clip(1e-12)
    _, _, vt = np.linalg.svd(A, full_matrices=False)
    h = vt[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[:, :3] / h[:, 3:4]


def check_points(
    points: np.ndarray, obs: np.ndarray, observers: list[Observer], min_angle_deg: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which points pass: in front of every observer, reprojection within each observer's
    tolerance, largest pairwise ray angle >= ``min_angle_deg``; and the RMS error (px)."""
    n = len(points)
    ok = np.all(np.isfinite(points), axis=1)
    sq = np.zeros(n)
    count = np.zeros(n)
    dirs = np.full((n, len(observers), 3), np.nan)
    for k, ob in enumerate(observers):
        seen = ~np.isnan(obs[:, k, 0])
        depth = points @ ob.pose.R[2] + ob.pose.t[2]
        ok &= ~seen | (depth > 0)
        uv = project(ob.intrinsics, ob.pose, points)
        err = np.linalg.norm(uv - obs[:, k], axis=1)
        with np.errstate(invalid="ignore"):
            ok &= ~seen | (err <= ob.tolerance_px)
        sq[seen] += np.nan_to_num(err[seen]) ** 2
        count[seen] += 1
        d = ob.pose.center - points
        dirs[seen, k] = d[seen] / np.linalg.norm(d[seen], axis=1, keepdims=True)
    cos_min = np.ones(n)
    for a in range(len(observers)):
        for b in range(a + 1, len(observers)):
            c = np.einsum("ij,ij->i", dirs[:, a], dirs[:, b])
            cos_min = np.fmin(cos_min, c)
    ok &= cos_min <= np.cos(np.radians(min_angle_deg))
    return ok, np.sqrt(sq / np.maximum(count, 1))


def block_centroids(
    dec: GrayDecoding, merge: tuple[int, int] = (1, 1)
) -> dict[str, np.ndarray]:
    """Projector blocks seen by a view (``keys``) and the mean camera pixel (``xy``) and pixel
    count (``counts``) of the pixels decoded to each.

    ``merge`` coarsens the blocks (views of one placement may resolve different bit counts).
    Keys are ``col * rows + row`` in the coarsened blocks; (x, y) in COLMAP pixel coordinates.
    """
    rows_, cols_ = np.nonzero(dec.valid)
    col = dec.col[rows_, cols_] // merge[0]
    row = dec.row[rows_, cols_] // merge[1]
    n_rows = -(-dec.blocks[1] // merge[1])
    key = col * n_rows + row
    uniq, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    x = np.bincount(inv, weights=cols_ + 0.5) / counts
    y = np.bincount(inv, weights=rows_ + 0.5) / counts
    return {"keys": uniq, "xy": np.stack([x, y], axis=1), "counts": counts}


def match_blocks(per_view: list[dict[str, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Union of block keys over views -> (keys (N,), pixels (N, V, 2) NaN where unseen)."""
    keys = np.unique(np.concatenate([c["keys"] for c in per_view]))
    obs = np.full((len(keys), len(per_view), 2), np.nan)
    for k, c in enumerate(per_view):
        obs[np.searchsorted(keys, c["keys"]), k] = c["xy"]
    return keys, obs
