"""Cameras and poses in COLMAP's conventions (docs/architecture.md, Cameras and poses).

World->camera ``x_c = R x_w + t``; pixel centre of the top-left pixel at (0.5, 0.5), so an
image array index ``[row, col]`` covers pixel coordinates ``[col, col+1) x [row, row+1)``.
Models and parameter order follow COLMAP's ``cameras.txt``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from core.errors import RigError

# COLMAP model name -> parameter names, in COLMAP's order.
CAMERA_MODELS: dict[str, tuple[str, ...]] = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
}


@dataclass(frozen=True)
class Intrinsics:
    """A COLMAP camera: model, image size and parameters."""

    model: str
    width: int
    height: int
    params: tuple[float, ...]

    def __post_init__(self) -> None:
        if self.model not in CAMERA_MODELS:
            raise RigError(
                f"camera model {self.model!r} is not supported",
                f"use one of {', '.join(CAMERA_MODELS)}",
            )
        if len(self.params) != len(CAMERA_MODELS[self.model]):
            raise RigError(
                f"camera model {self.model} needs {len(CAMERA_MODELS[self.model])} parameters "
                f"({', '.join(CAMERA_MODELS[self.model])}), got {len(self.params)}"
            )

    @classmethod
    def pinhole(cls, width: int, height: int, focal_px: float) -> Intrinsics:
        """An ideal pinhole with the principal point at the image centre."""
        return cls("PINHOLE", width, height, (focal_px, focal_px, width / 2.0, height / 2.0))

    def _named(self) -> dict[str, float]:
        return dict(zip(CAMERA_MODELS[self.model], self.params, strict=True))

    @property
    def K(self) -> np.ndarray:
        p = self._named()
        fx = p.get("fx", p.get("f"))
        fy = p.get("fy", p.get("f"))
        return np.array([[fx, 0.0, p["cx"]], [0.0, fy, p["cy"]], [0.0, 0.0, 1.0]])

    def distortion(self) -> np.ndarray:
        """OpenCV distortion coefficients (k1, k2, p1, p2) equivalent to this model."""
        p = self._named()
        return np.array(
            [
                p.get("k1", p.get("k", 0.0)),
                p.get("k2", 0.0),
                p.get("p1", 0.0),
                p.get("p2", 0.0),
            ]
        )

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Normalised image coordinates (N, 2) -> distorted normalised coordinates."""
        k1, k2, p1, p2 = self.distortion()
        if not (k1 or k2 or p1 or p2):
            return xy
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + k1 * r2 + k2 * r2 * r2
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=1)

    def undistort(self, xy_d: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Inverse of :meth:`distort` by fixed-point iteration (as COLMAP does)."""
        if not self.distortion().any():
            return xy_d
        xy = xy_d.copy()
        for _ in range(iterations):
            xy = xy + (xy_d - self.distort(xy))
        return xy

    def project_camera(self, points_cam: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) -> pixel coordinates (N, 2). Points behind give NaN."""
        z = points_cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = points_cam[:, :2] / z[:, None]
        xy[z <= 0] = np.nan
        xy = self.distort(xy)
        K = self.K
        return np.stack([K[0, 0] * xy[:, 0] + K[0, 2], K[1, 1] * xy[:, 1] + K[1, 2]], axis=1)

    def pixel_rays(self, uv: np.ndarray) -> np.ndarray:
        """Pixel coordinates (N, 2) -> unit viewing directions in the camera frame (N, 3)."""
        K = self.K
        xy_d = np.stack([(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1]], axis=1)
        xy = self.undistort(xy_d)
        d = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def in_image(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Which pixel coordinates fall inside the image (NaN counts as outside)."""
        with np.errstate(invalid="ignore"):
            return (
                (uv[:, 0] >= margin)
                & (uv[:, 0] <= self.width - margin)
                & (uv[:, 1] >= margin)
                & (uv[:, 1] <= self.height - margin)
            )


@dataclass(frozen=True)
class Pose:
    """World->camera rigid transform ``x_c = R x_w + t``."""

    R: np.ndarray
    t: np.ndarray

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates, ``-R^T t``."""
        return -self.R.T @ self.t

    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        return points_world @ self.R.T + self.t

    def to_world(self, points_cam: np.ndarray) -> np.ndarray:
        return (points_cam - self.t) @ self.R

    def light_position(self, offset_cam: np.ndarray) -> np.ndarray:
        """World position of a light rigidly mounted at ``offset_cam`` (camera frame):
        ``p = R^T (v - t)`` (paper eq. 17)."""
        return self.R.T @ (np.asarray(offset_cam, dtype=float) - self.t)

    @property
    def qvec(self) -> np.ndarray:
        """Rotation as COLMAP's quaternion (qw, qx, qy, qz)."""
        x, y, z, w = Rotation.from_matrix(self.R).as_quat()
        q = np.array([w, x, y, z])
        return q if q[0] >= 0 else -q

    @classmethod
    def from_qvec_tvec(cls, qvec: np.ndarray, tvec: np.ndarray) -> Pose:
        qw, qx, qy, qz = qvec
        R = Rotation.from_quat([qx, qy, qz, qw]).as_matrix()
        return cls(R, np.asarray(tvec, dtype=float))

    @classmethod
    def look_at(
        cls, eye: np.ndarray, target: np.ndarray, up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    ) -> Pose:
        """A camera at ``eye`` looking at ``target`` (camera y points down, image-up ~ ``up``)."""
        eye = np.asarray(eye, dtype=float)
        z = np.asarray(target, dtype=float) - eye
        z /= np.linalg.norm(z)
        x = np.cross(z, np.asarray(up, dtype=float))
        if np.linalg.norm(x) < 1e-9:
            x = np.cross(z, np.array([0.0, 1.0, 0.0]))
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.stack([x, y, z])
        return cls(R, -R @ eye)


def project(intrinsics: Intrinsics, pose: Pose, points_world: np.ndarray) -> np.ndarray:
    """World points (N, 3) -> pixel coordinates (N, 2); NaN behind the camera."""
    return intrinsics.project_camera(pose.to_camera(points_world))


# --- COLMAP text model -------------------------------------------------------------------


def write_colmap_text(
    folder: Path,
    cameras: dict[int, Intrinsics],
    images: dict[int, tuple[int, str, Pose]],
) -> None:
    """Write ``cameras.txt``, ``images.txt`` and an empty ``points3D.txt``.

    ``images`` maps image id -> (camera id, image name, pose).
    """
    folder.mkdir(parents=True, exist_ok=True)
    lines = [
        "# Camera list with one line of data per camera:",
        "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
    ]
    for cid, cam in sorted(cameras.items()):
        params = " ".join(repr(float(p)) for p in cam.params)
        lines.append(f"{cid} {cam.model} {cam.width} {cam.height} {params}")
    (folder / "cameras.txt").write_text("\n".join(lines) + "\n")
    lines = [
        "# Image list with two lines of data per image:",
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
        "#   POINTS2D[] as (X, Y, POINT3D_ID)",
    ]
    for iid, (cid, name, pose) in sorted(images.items()):
        q = " ".join(repr(float(v)) for v in pose.qvec)
        t = " ".join(repr(float(v)) for v in pose.t)
        lines.append(f"{iid} {q} {t} {cid} {name}")
        lines.append("")
    (folder / "images.txt").write_text("\n".join(lines) + "\n")
    (folder / "points3D.txt").write_text("# 3D point list (empty)\n")


def read_colmap_text(
    folder: Path,
) -> tuple[dict[int, Intrinsics], dict[int, tuple[int, str, Pose]]]:
    """Read ``cameras.txt`` and ``images.txt`` of a COLMAP text model."""
    cameras: dict[int, Intrinsics] = {}
    images: dict[int, tuple[int, str, Pose]] = {}
    for name in ("cameras.txt", "images.txt"):
        if not (folder / name).is_file():
            raise RigError(
                f"{folder / name} is missing",
                "a COLMAP text model needs cameras.txt and images.txt",
            )
    for n, line in enumerate((folder / "cameras.txt").read_text().splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        f = line.split()
        try:
            cameras[int(f[0])] = Intrinsics(f[1], int(f[2]), int(f[3]), tuple(map(float, f[4:])))
        except (ValueError, IndexError) as exc:
            raise RigError(f"{folder / 'cameras.txt'} line {n} is malformed: {exc}") from exc
    data = [ln for ln in (folder / "images.txt").read_text().splitlines() if not ln.startswith("#")]
    for n in range(0, len(data), 2):
        f = data[n].split()
        if not f:
            continue
        try:
            pose = Pose.from_qvec_tvec(np.array(f[1:5], float), np.array(f[5:8], float))
            images[int(f[0])] = (int(f[8]), f[9], pose)
        except (ValueError, IndexError) as exc:
            raise RigError(f"{folder / 'images.txt'} entry {f[:1]} is malformed: {exc}") from exc
    return cameras, images
