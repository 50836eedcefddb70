"""The projector as a camera: its intrinsics and pose per placement from triangulated points
and the projector pixels that lit them (linear resection, then PnP), and the light position
each view gets from the placement that lit it."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import cv2
import numpy as np
from scipy.linalg import rq

from core.errors import RigError
from reconstruct.model.camera import Intrinsics, Pose


def resect(points: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, Pose]:
    """Camera matrix by normalised linear DLT from >= 6 non-coplanar points -> (K, pose)."""
    def normaliser(p: np.ndarray) -> np.ndarray:
        c = p.mean(axis=0)
        s = np.sqrt(p.shape[1]) / np.linalg.norm(p - c, axis=1).mean()
        T = np.eye(p.shape[1] + 1)
        T[:-1, :-1] *= s
        T[:-1, -1] = -s * c
        return T

    T3, T2 = normaliser(points), normaliser(xy)
    X = (np.hstack([points, np.ones((len(points), 1))])) @ T3.T
    x = (np.hstack([xy, np.ones((len(xy), 1))])) @ T2.T
    zeros = np.zeros_like(X)
    A = np.concatenate(
        [
            np.hstack([X, zeros, -x[:, :1] * X]),
            np.hstack([zeros, X, -x[:, 1:2] * X]),
        ]
    )
    P = np.linalg.solve(T2, np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 4) @ T3)
    if np.linalg.det(P[:, :3]) < 0:
        P = -P
    K, R = rq(P[:, :3])
    D = np.diag(np.sign(np.diag(K)))
    K, R = K @ D, D @ R
    t = np.linalg.solve(K, P[:, 3])
    return K / K[2, 2], Pose(R, t)


def projector_pose(
    points: np.ndarray, xy: np.ndarray, size: tuple[int, int], focal_px: float | None,
    tolerance_px: float,
) -> tuple[Intrinsics, Pose, int]:
    """Projector intrinsics and pose from 3-D points and their projector pixels: resection for
    an initial camera matrix, then ``cv2.solvePnPRansac`` with a square-pixel K (the given
    focal, else the resected one) and the principal point at the image centre; an unknown
    focal is finally refined jointly with the pose (``cv2.calibrateCamera``, one view of
    non-coplanar points, everything but f and the pose held fixed)."""
    if len(points) < 12:
        raise RigError(
            f"only {len(points)} triangulated points lit by one projector placement",
            "let more of the object be lit from each placement, or take more views per placement",
        )
    known = focal_px is not None
    if focal_px is None:
        K0, _ = resect(points, xy)
        focal_px = float(np.sqrt(abs(K0[0, 0] * K0[1, 1])))
    intr = Intrinsics.pinhole(size[0], size[1], focal_px)
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(
        points.astype(np.float64), xy.astype(np.float64), intr.K, None,
        reprojectionError=tolerance_px, iterationsCount=200, flags=cv2.SOLVEPNP_EPNP,
    )
    if not ok or inliers is None:
        raise RigError("the projector pose could not be estimated", "check the camera poses")
    idx = inliers[:, 0]
    obj, img = points[idx].astype(np.float32), xy[idx].astype(np.float32)
    if not known:
        flags = (
            cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT
            | cv2.CALIB_FIX_ASPECT_RATIO | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1
            | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3
        )
        _, K, _, rvecs, tvecs = cv2.calibrateCamera(
            [obj], [img], size, intr.K.copy(), np.zeros(5), flags=flags
        )
        intr = Intrinsics.pinhole(size[0], size[1], float(K[0, 0]))
        rvec, tvec = rvecs[0], tvecs[0]
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, intr.K, None, rvec, tvec)
    return intr, Pose(cv2.Rodrigues(rvec)[0], np.asarray(tvec, float).ravel()), len(idx)


def light_positions(
    view_placement: Mapping[int, Any], placement_poses: Mapping[Any, Pose]
) -> dict[int, np.ndarray]:
    """Per-view light position (world, metres): the optical centre of the projector
    placement that lit the view — the near point light of the optimiser's free-light mode."""
    return {
        v: placement_poses[p].center for v, p in view_placement.items() if p in placement_poses
    }
