"""Cameras and poses in COLMAP's conventions (docs/architecture.md, Cameras and poses).

World->camera ``x_c = R x_w + t``; pixel centre of the top-left pixel at (0.5, 0.5), so an
image array index ``[row, col]`` covers pixel coordinates ``[col, col+1) x [row, row+1)``.
Models and parameter order follow COLMAP's ``cameras.txt``.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

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
    """Write a COLMAP text model with pycolmap: ``cameras.txt``, ``images.txt``, an empty
    ``points3D.txt``, and ``rigs.txt``/``frames.txt`` (one camera per rig, one image per frame).

    ``images`` maps image id -> (camera id, image name, pose).
    """
    import pycolmap

    model = pycolmap.Reconstruction()
    for cid, cam in sorted(cameras.items()):
        model.add_camera_with_trivial_rig(
            pycolmap.Camera(
                camera_id=cid,
                model=cam.model,
                width=cam.width,
                height=cam.height,
                params=list(cam.params),
            )
        )
    for iid, (cid, name, pose) in sorted(images.items()):
        cam_from_world = pycolmap.Rigid3d(pycolmap.Rotation3d(pose.R), pose.t)
        model.add_image_with_trivial_frame(
            pycolmap.Image(name=name, camera_id=cid, image_id=iid), cam_from_world
        )
    folder.mkdir(parents=True, exist_ok=True)
    model.write_text(folder)


def read_colmap_text(
    folder: Path,
) -> tuple[dict[int, Intrinsics], dict[int, tuple[int, str, Pose]]]:
    """The cameras and posed images of a COLMAP text model, read with pycolmap."""
    import pycolmap

    for name in ("cameras.txt", "images.txt"):
        if not (folder / name).is_file():
            raise RigError(
                f"{folder / name} is missing",
                "a COLMAP text model needs cameras.txt and images.txt",
            )
    model = pycolmap.Reconstruction()
    try:
        with _with_points3d(folder) as readable:
            model.read_text(readable)
    except ValueError as error:  # pycolmap's failed format checks
        raise RigError(
            f"{folder} is not a valid COLMAP text model: {str(error).splitlines()[0]}",
            "write cameras.txt and images.txt in COLMAP's text format "
            "(docs/architecture.md#session-format)",
        ) from error
    cameras = {
        cid: Intrinsics(cam.model.name, cam.width, cam.height, tuple(map(float, cam.params)))
        for cid, cam in model.cameras.items()
    }
    images: dict[int, tuple[int, str, Pose]] = {}
    for iid, image in model.images.items():
        if image.has_pose:
            rigid = image.cam_from_world()
            pose = Pose(np.asarray(rigid.rotation.matrix()), np.asarray(rigid.translation))
            images[iid] = (image.camera_id, image.name, pose)
    return cameras, images


@contextmanager
def _with_points3d(folder: Path) -> Iterator[Path]:
    """``folder``, or a copy of its cameras and images with an empty ``points3D.txt``: pycolmap
    needs one, and known poses written by hand often have none."""
    if (folder / "points3D.txt").is_file():
        yield folder
        return
    with tempfile.TemporaryDirectory() as scratch:
        for name in ("cameras.txt", "images.txt", "rigs.txt", "frames.txt"):
            if (folder / name).is_file():
                shutil.copyfile(folder / name, Path(scratch) / name)
        (Path(scratch) / "points3D.txt").touch()
        yield Path(scratch)
