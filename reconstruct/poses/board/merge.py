"""Bringing SfM poses into the board's metric, gravity-aligned frame.

SfM registers views where the board is hidden (the object in front of it, steep angles);
the board fixes scale, up and origin. A similarity (Umeyama 1991) maps SfM camera centres
onto the board's for the views both posed; every SfM-only view is carried across with it.
"""

from __future__ import annotations

import itertools
from collections.abc import Hashable, Mapping
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np
from scipy.spatial.transform import Rotation

from core.errors import RigError
from reconstruct.model.camera import Pose
from reconstruct.poses.board.poses import BoardPoseResult, corner_residuals, rms_of

ViewKey = TypeVar("ViewKey", bound=Hashable)


@dataclass(frozen=True)
class Similarity:
    """``x' = scale * R x + t``."""

    scale: float
    R: np.ndarray
    t: np.ndarray

    def apply(self, points: np.ndarray) -> np.ndarray:
        return self.scale * np.asarray(points, dtype=float) @ self.R.T + self.t

    def apply_pose(self, pose: Pose) -> Pose:
        """A world->camera pose in the source frame -> the same camera in the target frame
        (camera-frame lengths rescaled to the target's units)."""
        R = pose.R @ self.R.T
        return Pose(R, self.scale * pose.t - R @ self.t)

    def inverse(self) -> Similarity:
        R = self.R.T
        return Similarity(1.0 / self.scale, R, -(R @ self.t) / self.scale)


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = True) -> Similarity:
    """Least-squares similarity mapping ``src`` (N, 3) onto ``dst`` (N, 3) (Umeyama 1991)."""
    src, dst = np.asarray(src, dtype=float), np.asarray(dst, dtype=float)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3:
        raise ValueError(f"umeyama needs two (N, 3) arrays, got {src.shape} and {dst.shape}")
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    sc, dc = src - mu_s, dst - mu_d
    sv = np.linalg.svd(sc, compute_uv=False)
    if len(src) < 3 or sv[1] < 1e-9 * max(sv[0], 1e-300):
        raise RigError(
            f"the {len(src)} camera centres shared by SfM and the board are collinear or too "
            "few to fix a rotation",
            "capture the board from at least three positions that are not on one line",
        )
    U, D, Vt = np.linalg.svd(dc.T @ sc / len(src))
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1.0
    R = U @ S @ Vt
    scale = float(np.trace(np.diag(D) @ S) / np.mean(np.sum(sc**2, axis=1))) if with_scale else 1.0
    return Similarity(scale, R, mu_d - scale * R @ mu_s)


@dataclass
class MergedPoses(Generic[ViewKey]):
    """Every view posed by the board or by SfM, in the board's world frame.

    ``source[k]`` is "board" or "sfm"; ``reprojection_px[k]`` is the RMS board-corner error of
    the final pose (NaN where the view shows no board corner); ``alignment_residual_m`` and
    ``alignment_rotation_deg`` compare, for the shared views, the carried-across SfM pose with
    the board's; ``alignment_outliers`` are shared views left out of the fit.
    """

    poses: dict[ViewKey, Pose]
    source: dict[ViewKey, str]
    reprojection_px: dict[ViewKey, float]
    alignment_residual_m: dict[ViewKey, float]
    alignment_rotation_deg: dict[ViewKey, float]
    alignment_outliers: list[ViewKey]
    similarity: Similarity

    def summary(self) -> dict[str, object]:
        """JSON-ready: the SfM->board similarity and, per view, source and errors."""
        views: dict[str, dict[str, object]] = {}
        for key in self.poses:
            entry: dict[str, object] = {"source": self.source[key]}
            error = self.reprojection_px[key]
            entry["reprojection_px"] = None if np.isnan(error) else round(error, 4)
            if key in self.alignment_residual_m:
                entry["alignment_residual_mm"] = round(1000 * self.alignment_residual_m[key], 3)
                entry["alignment_rotation_deg"] = round(self.alignment_rotation_deg[key], 4)
                entry["alignment_outlier"] = key in self.alignment_outliers
            views[str(key)] = entry
        return {
            "sfm_to_board": {
                "scale": self.similarity.scale,
                "R": self.similarity.R.tolist(),
                "t": self.similarity.t.tolist(),
            },
            "views": views,
        }


def merge_with_sfm(
    board_result: BoardPoseResult[ViewKey],
    sfm_poses: Mapping[ViewKey, Pose],
    *,
    inlier_m: float = 0.01,
    max_samples: int = 500,
) -> MergedPoses[ViewKey]:
    """Board poses where the board posed the view, SfM poses mapped into the board frame
    elsewhere. The similarity is found robustly (the best of up to ``max_samples`` triples of
    shared views, then refitted on every shared view within ``inlier_m`` of the board's
    centre), so a misregistered SfM view cannot tilt or scale the whole set."""
    common = [k for k in board_result.poses if k in sfm_poses]
    if len(common) < 3:
        raise RigError(
            f"only {len(common)} views are posed by both SfM and the board (need 3) to bring "
            "SfM into the board frame",
            "capture more views where the board is visible, or use the board poses alone",
        )
    src = np.array([sfm_poses[k].center for k in common])
    dst = np.array([board_result.poses[k].center for k in common])
    keep = _consensus(src, dst, inlier_m, max_samples)
    if keep.sum() < 3:
        raise RigError(
            f"SfM and board poses agree (within {inlier_m * 1000:g} mm) on only "
            f"{int(keep.sum())} of {len(common)} shared views",
            "check the board spec (square size) and the SfM model; views may be misregistered",
        )
    sim = umeyama(src[keep], dst[keep])
    residual = np.linalg.norm(sim.apply(src) - dst, axis=1)
    poses: dict[ViewKey, Pose] = dict(board_result.poses)
    source = dict.fromkeys(board_result.poses, "board")
    for key, pose in sfm_poses.items():
        if key not in poses:
            poses[key], source[key] = sim.apply_pose(pose), "sfm"
    rotation_deg = {}
    for key in common:
        carried = sim.apply_pose(sfm_poses[key]).R
        difference = Rotation.from_matrix(carried.T @ board_result.poses[key].R)
        rotation_deg[key] = float(np.degrees(difference.magnitude()))
    errors = {}
    for key, pose in poses.items():
        if key in board_result.reprojection_px:
            errors[key] = board_result.reprojection_px[key]
            continue
        det = board_result.detections.get(key)
        errors[key] = (
            rms_of(corner_residuals(board_result.intrinsics, pose, det))
            if det is not None and det.n_corners > 0
            else np.nan
        )
    return MergedPoses(
        poses=poses,
        source=source,
        reprojection_px=errors,
        alignment_residual_m={k: float(r) for k, r in zip(common, residual, strict=True)},
        alignment_rotation_deg=rotation_deg,
        alignment_outliers=[k for k, ok in zip(common, keep, strict=True) if not ok],
        similarity=sim,
    )


def _consensus(src: np.ndarray, dst: np.ndarray, inlier_m: float, max_samples: int) -> np.ndarray:
    """Inlier mask of the similarity from the triple of views most others agree with."""
    n = len(src)
    triples = np.array(list(itertools.combinations(range(n), 3)))
    if len(triples) > max_samples:
        rng = np.random.default_rng(0)
        triples = triples[rng.choice(len(triples), max_samples, replace=False)]
    best, best_score = np.zeros(n, dtype=bool), (0, 0.0)
    for triple in triples:
        try:
            sim = umeyama(src[triple], dst[triple])
        except RigError:
            continue  # three centres on a line
        residual = np.linalg.norm(sim.apply(src) - dst, axis=1)
        inliers = residual <= inlier_m
        score = (int(inliers.sum()), -float(residual[inliers].sum()))
        if score > best_score:
            best, best_score = inliers, score
    if best_score[0] < 3:
        return best
    # Refit on the consensus and take everything it explains.
    sim = umeyama(src[best], dst[best])
    return np.linalg.norm(sim.apply(src) - dst, axis=1) <= inlier_m
