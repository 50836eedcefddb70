"""Camera poses (and, when unknown, intrinsics) from ChArUco detections.

Each view: planar PnP (IPPE, both solutions tried, camera kept above the paper) then
Levenberg-Marquardt. All views: one robust least-squares adjustment over the poses and,
optionally, the intrinsics, with the board points fixed: the board is the metric ruler.
Poses are world->camera in the board's world frame (z up, origin at the board centre).
"""

from __future__ import annotations

import logging
from collections.abc import Hashable, Mapping
from dataclasses import dataclass, field, replace
from typing import Generic, TypeVar

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from core.errors import RigError
from reconstruct.model.camera import CAMERA_MODELS, Intrinsics, Pose
from reconstruct.poses.board.detect import Detection

log = logging.getLogger("reconstruct.poses.board")

ViewKey = TypeVar("ViewKey", bound=Hashable)

# cv2.calibrateCamera flags that make its distortion model match each COLMAP model.
_FIX_ALL_DIST = cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3
_CALIB_FLAGS: dict[str, int] = {
    "SIMPLE_PINHOLE": _FIX_ALL_DIST | cv2.CALIB_FIX_ASPECT_RATIO,
    "PINHOLE": _FIX_ALL_DIST,
    "SIMPLE_RADIAL": cv2.CALIB_ZERO_TANGENT_DIST
    | cv2.CALIB_FIX_K2
    | cv2.CALIB_FIX_K3
    | cv2.CALIB_FIX_ASPECT_RATIO,
    "RADIAL": cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3 | cv2.CALIB_FIX_ASPECT_RATIO,
    "OPENCV": cv2.CALIB_FIX_K3,
}
MIN_CALIBRATION_VIEWS = 4


@dataclass
class BoardPoseResult(Generic[ViewKey]):
    """Board poses for the views that had enough corners, plus why the others have none."""

    intrinsics: Intrinsics
    intrinsics_source: str
    poses: dict[ViewKey, Pose]
    reprojection_px: dict[ViewKey, float]  # RMS over the view's corners, after the adjustment
    n_corners: dict[ViewKey, int]  # every view, posed or not
    rejected: dict[ViewKey, str] = field(default_factory=dict)
    detections: dict[ViewKey, Detection] = field(default_factory=dict)
    outlier_corners: dict[ViewKey, int] = field(default_factory=dict)  # dropped as inconsistent

    @property
    def rms_px(self) -> float:
        """RMS reprojection error over all posed corners."""
        if not self.poses:
            return float("nan")
        used = {k: self.n_corners[k] - self.outlier_corners.get(k, 0) for k in self.poses}
        sq = sum(self.reprojection_px[k] ** 2 * n for k, n in used.items())
        return float(np.sqrt(sq / sum(used.values())))

    def summary(self) -> dict[str, dict[str, object]]:
        """Per view, JSON-ready: corners seen and dropped, RMS error or why it was not posed."""
        out: dict[str, dict[str, object]] = {}
        for key, n in self.n_corners.items():
            entry: dict[str, object] = {
                "corners": n,
                "outlier_corners": self.outlier_corners.get(key, 0),
            }
            if key in self.poses:
                entry["reprojection_px"] = round(self.reprojection_px[key], 4)
            else:
                entry["rejected"] = self.rejected.get(key, "")
            out[str(key)] = entry
        return out


def corner_residuals(intrinsics: Intrinsics, pose: Pose, detection: Detection) -> np.ndarray:
    """Reprojected minus detected corner positions (N, 2), in pixels."""
    uv = intrinsics.project_camera(pose.to_camera(detection.object_points))
    return np.nan_to_num(uv - detection.corners, nan=1e4)


def rms_of(residuals: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(residuals**2, axis=1)))) if len(residuals) else np.nan


def _intrinsics_from_opencv(
    model: str, size: tuple[int, int], K_cv: np.ndarray, dist: np.ndarray
) -> Intrinsics:
    fx, fy, cx, cy = K_cv[0, 0], K_cv[1, 1], K_cv[0, 2], K_cv[1, 2]
    k1, k2, p1, p2 = (np.ravel(dist).tolist() + [0.0] * 4)[:4]
    f = (fx + fy) / 2
    values = {
        "f": f,
        "fx": fx,
        "fy": fy,
        "cx": cx,
        "cy": cy,
        "k": k1,
        "k1": k1,
        "k2": k2,
        "p1": p1,
        "p2": p2,
    }
    params = tuple(float(values[name]) for name in CAMERA_MODELS[model])
    return Intrinsics(model, size[0], size[1], params)


def estimate_intrinsics(
    detections: Mapping[ViewKey, Detection],
    image_size: tuple[int, int],
    model: str = "RADIAL",
    initial: Intrinsics | None = None,
) -> Intrinsics:
    """Zhang's calibration (``cv2.calibrateCamera``) from board views at several angles,
    starting from ``initial`` (its model) when given. Pixel coordinates stay in COLMAP's
    convention, so the principal point comes out in it."""
    if initial is not None:
        model = initial.model
    if model not in _CALIB_FLAGS:
        raise RigError(
            f"camera model {model} cannot be estimated from the board",
            f"use one of {', '.join(_CALIB_FLAGS)}",
        )
    views = [d for d in detections.values() if d.n_corners >= 6]
    if len(views) < MIN_CALIBRATION_VIEWS:
        raise RigError(
            f"only {len(views)} views show the board well enough to estimate the camera "
            f"intrinsics (need {MIN_CALIBRATION_VIEWS})",
            "capture more views with the whole board visible at varied tilts, or give the "
            "intrinsics in the profile",
        )
    obj = [d.object_points.astype(np.float32) for d in views]
    img = [d.corners.astype(np.float32) for d in views]
    flags = _CALIB_FLAGS[model]
    K0, dist0 = np.eye(3), np.zeros(5)
    if initial is not None:
        K0, dist0 = initial.K.copy(), np.append(initial.distortion(), 0.0)
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
    rms, K_cv, dist, _, _ = cv2.calibrateCamera(obj, img, image_size, K0, dist0, flags=flags)
    log.info("calibrateCamera (%s) from %d views: RMS %.3f px", model, len(views), rms)
    return _intrinsics_from_opencv(model, image_size, K_cv, dist)


def solve_view_pose(intrinsics: Intrinsics, detection: Detection) -> Pose:
    """Planar PnP for one view: both IPPE solutions, keeping the one with the camera above
    the printed side and the smaller error, then iterative (LM) refinement."""
    K_cv, dist = intrinsics.K, intrinsics.distortion()
    obj = detection.object_points.astype(np.float64)
    img = detection.corners.astype(np.float64)
    _, rvecs, tvecs, errors = cv2.solvePnPGeneric(obj, img, K_cv, dist, flags=cv2.SOLVEPNP_IPPE)
    best: tuple[float, np.ndarray, np.ndarray] | None = None
    for rvec, tvec, err in zip(rvecs, tvecs, np.ravel(errors), strict=True):
        pose = Pose(cv2.Rodrigues(rvec)[0], tvec.ravel())
        if pose.center[2] > 0 and (best is None or err < best[0]):
            best = (float(err), rvec, tvec)
    if best is None:
        raise RigError(
            "no board pose puts the camera above the board",
            "check that the board spec matches the printed board",
        )
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K_cv, dist, best[1].copy(), best[2].copy())
    return Pose(cv2.Rodrigues(rvec)[0], tvec.ravel())


def adjust(
    intrinsics: Intrinsics,
    poses: list[Pose],
    detections: list[Detection],
    refine_intrinsics: bool,
    huber_px: float = 1.0,
) -> tuple[Intrinsics, list[Pose]]:
    """Joint robust adjustment of all poses (and the intrinsics, if asked) with the board
    points fixed. Sparse Jacobian: each corner depends on its view's 6 parameters only."""
    n_views = len(poses)
    view_of = np.concatenate([np.full(d.n_corners, v) for v, d in enumerate(detections)])
    obj = np.concatenate([d.object_points for d in detections])
    observed = np.concatenate([d.corners for d in detections])
    n_intr = len(intrinsics.params) if refine_intrinsics else 0
    x0 = np.concatenate(
        [np.concatenate([Rotation.from_matrix(p.R).as_rotvec(), p.t]) for p in poses]
        + [np.asarray(intrinsics.params[:n_intr], dtype=float)]
    )

    def unpack(x: np.ndarray) -> tuple[Intrinsics, np.ndarray]:
        intr = intrinsics
        if n_intr:
            intr = Intrinsics(
                intrinsics.model,
                intrinsics.width,
                intrinsics.height,
                tuple(x[6 * n_views :].tolist()),
            )
        return intr, x[: 6 * n_views].reshape(n_views, 6)

    def residuals(x: np.ndarray) -> np.ndarray:
        intr, views = unpack(x)
        cam = Rotation.from_rotvec(views[view_of, :3]).apply(obj) + views[view_of, 3:]
        return np.nan_to_num(intr.project_camera(cam) - observed, nan=1e4).ravel()

    sparsity = lil_matrix((2 * len(obj), len(x0)), dtype=np.int8)
    rows = np.arange(len(obj))
    for k in range(6):
        sparsity[2 * rows, 6 * view_of + k] = 1
        sparsity[2 * rows + 1, 6 * view_of + k] = 1
    if n_intr:
        sparsity[:, 6 * n_views :] = 1
    fit = least_squares(
        residuals,
        x0,
        jac_sparsity=sparsity,
        method="trf",
        loss="huber",
        f_scale=huber_px,
        x_scale="jac",
        xtol=1e-10,
        ftol=1e-8,
        max_nfev=200,
    )
    log.debug("board adjustment: %s after %d evaluations", fit.message, fit.nfev)
    intr, views = unpack(fit.x)
    out = [Pose(Rotation.from_rotvec(v[:3]).as_matrix(), v[3:].copy()) for v in views]
    return intr, out


def board_poses(
    detections: Mapping[ViewKey, Detection],
    intrinsics: Intrinsics | None,
    image_size: tuple[int, int],
    *,
    min_corners: int = 6,
    model: str = "RADIAL",
    refine_intrinsics: bool | None = None,
    max_rms_px: float = 3.0,
    outlier_factor: float = 3.5,
    outlier_floor_px: float = 0.25,
    max_rejection_rounds: int = 4,
) -> BoardPoseResult[ViewKey]:
    """Poses of every view that sees at least ``min_corners`` non-collinear board corners.

    ``intrinsics`` from the profile, or ``None`` to estimate them (``model``) from the board
    views. ``refine_intrinsics`` (default: only when estimated) frees them in the joint
    adjustment. Corners whose error exceeds ``outlier_factor`` x the median corner error (and
    ``outlier_floor_px``) are dropped, re-decided each round, and counted in
    ``outlier_corners``; views whose RMS error stays above ``max_rms_px`` are not posed.
    """
    width, height = image_size
    n_corners = {k: d.n_corners for k, d in detections.items()}
    rejected: dict[ViewKey, str] = {}
    usable: dict[ViewKey, Detection] = {}
    for key, det in detections.items():
        if det.image_size != (width, height):
            raise RigError(
                f"view {key}: board detected in a {det.image_size[0]}x{det.image_size[1]} image, "
                f"expected {width}x{height}",
                "detect the board in full-resolution frames of one camera",
            )
        if det.n_corners < max(min_corners, 4):
            rejected[key] = f"too few board corners ({det.n_corners} < {max(min_corners, 4)})"
        elif _collinear(det.object_points):
            rejected[key] = "board corners all on one line"
        else:
            usable[key] = det
    if intrinsics is None:
        intrinsics = estimate_intrinsics(usable, image_size, model)
        source = f"estimated from {len(usable)} board views ({model})"
        refine = True if refine_intrinsics is None else refine_intrinsics
    else:
        if (intrinsics.width, intrinsics.height) != (width, height):
            raise RigError(
                f"the profile's intrinsics are for {intrinsics.width}x{intrinsics.height} "
                f"images but the frames are {width}x{height}",
                "give intrinsics for the decoded frame size, or omit them to estimate them",
            )
        source = "given"
        refine = bool(refine_intrinsics)
        if refine and intrinsics.model in _CALIB_FLAGS:
            # Zhang's method walks the focal length / distance valley faster than the
            # robust adjustment below, which then only polishes.
            intrinsics = estimate_intrinsics(usable, image_size, initial=intrinsics)
            source = "given, refined on the board views"
    if not usable:
        return BoardPoseResult(intrinsics, source, {}, {}, n_corners, rejected, dict(detections))
    keys = list(usable)
    full = [usable[k] for k in keys]
    adjusted = [solve_view_pose(intrinsics, d) for d in full]
    # Corners far outside the common noise level (one caught on the object's outline) are
    # left out and the adjustment repeated, until the set of kept corners settles.
    inliers = [np.ones(d.n_corners, dtype=bool) for d in full]
    for round_ in range(max(1, max_rejection_rounds)):
        views = [_subset(d, m) for d, m in zip(full, inliers, strict=True)]
        intrinsics, adjusted = adjust(intrinsics, adjusted, views, refine)
        norms = [
            np.linalg.norm(corner_residuals(intrinsics, p, d), axis=1)
            for p, d in zip(adjusted, full, strict=True)
        ]
        limit = max(outlier_factor * float(np.median(np.concatenate(norms))), outlier_floor_px)
        settled = [n <= limit for n in norms]
        same = all(np.array_equal(a, b) for a, b in zip(settled, inliers, strict=True))
        if same or round_ == max_rejection_rounds - 1:
            break  # ``views``, ``adjusted`` and ``inliers`` describe the same corners
        inliers = settled
    outliers = {k: int((~m).sum()) for k, m in zip(keys, inliers, strict=True) if not m.all()}
    poses: dict[ViewKey, Pose] = {}
    errors: dict[ViewKey, float] = {}
    for key, pose, det in zip(keys, adjusted, views, strict=True):
        rms = rms_of(corner_residuals(intrinsics, pose, det))
        if rms > max_rms_px:
            rejected[key] = f"reprojection error {rms:.2f} px > {max_rms_px} px"
        elif det.n_corners < 4:
            rejected[key] = f"only {det.n_corners} board corners agree with the others"
        else:
            poses[key], errors[key] = pose, rms
    return BoardPoseResult(
        intrinsics, source, poses, errors, n_corners, rejected, dict(detections), outliers
    )


def _subset(det: Detection, keep: np.ndarray) -> Detection:
    return replace(
        det, ids=det.ids[keep], corners=det.corners[keep], object_points=det.object_points[keep]
    )


def _collinear(points: np.ndarray) -> bool:
    centred = points[:, :2] - points[:, :2].mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    return bool(s[-1] < 1e-6 * max(s[0], 1e-12))
