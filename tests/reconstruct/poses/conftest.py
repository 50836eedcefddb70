"""Synthetic camera views of the printed board, rendered from its texture with a known pose.

The sheet is warped into the image through the plane homography ``K [r1 r2 t]`` (pinhole),
then shaded, blurred, partly hidden by an "object" and given sensor noise, so detection and
pose tests run against images with a known truth.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
import pytest

from reconstruct.model.camera import Intrinsics, Pose, project
from reconstruct.poses.board import BoardSpec, board_texture

PX_PER_M = 6000.0
SUPERSAMPLE = 3  # render at 3x and area-average: a real sensor integrates over its pixels
PAPER, INK, BACKGROUND = 0.85, 0.05, 0.08


@dataclass(frozen=True)
class Scene:
    spec: BoardSpec
    texture: np.ndarray
    extent: tuple[float, float, float, float]
    intrinsics: Intrinsics


def plane_homography(scene: Scene, pose: Pose, K: np.ndarray) -> np.ndarray:
    """Texture pixel -> pinhole image pixel (both OpenCV's centre convention) for camera ``K``
    (COLMAP convention)."""
    x0, _, _, y1 = scene.extent
    tex_to_world = np.array(
        [
            [1 / PX_PER_M, 0.0, x0 + 0.5 / PX_PER_M],
            [0.0, -1 / PX_PER_M, y1 - 0.5 / PX_PER_M],
            [0.0, 0.0, 1.0],
        ]
    )
    world_to_colmap = K @ np.column_stack([pose.R[:, 0], pose.R[:, 1], pose.t])
    colmap_to_cv = np.array([[1.0, 0.0, -0.5], [0.0, 1.0, -0.5], [0.0, 0.0, 1.0]])
    return colmap_to_cv @ world_to_colmap @ tex_to_world


def render(
    scene: Scene,
    pose: Pose,
    rng: np.random.Generator,
    *,
    occluder_m: float = 0.06,
    blur_sigma: float = 0.8,
    noise_dn: float = 2.0,
    gain: float = 1.0,
) -> np.ndarray:
    """8-bit grey view of the board: warped sheet, light fall-off, an object standing on the
    board centre (a grey ellipse of radius ``occluder_m``), blur and noise."""
    intr = scene.intrinsics
    w, h = intr.width, intr.height
    distorted = bool(intr.distortion().any())
    pad = int(0.15 * max(w, h)) if distorted else 0  # barrel distortion pulls in a wider view
    K = intr.K + np.array([[0.0, 0.0, pad], [0.0, 0.0, pad], [0.0, 0.0, 0.0]])
    reflectance = INK + (PAPER - INK) * scene.texture
    k = SUPERSAMPLE
    fine = np.array([[k, 0.0, (k - 1) / 2], [0.0, k, (k - 1) / 2], [0.0, 0.0, 1.0]])
    pw, ph = w + 2 * pad, h + 2 * pad
    img = cv2.warpPerspective(
        reflectance.astype(np.float32),
        fine @ plane_homography(scene, pose, K),
        (k * pw, k * ph),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=BACKGROUND,
    )
    img = cv2.resize(img, (pw, ph), interpolation=cv2.INTER_AREA)
    if distorted:
        # Each output pixel looks along its undistorted ray: sample the pinhole image there.
        v, u = np.mgrid[0:h, 0:w].reshape(2, -1) + 0.5
        xy_d = np.stack([(u - intr.K[0, 2]) / intr.K[0, 0], (v - intr.K[1, 2]) / intr.K[1, 1]], 1)
        xy = intr.undistort(xy_d)
        map_x = (K[0, 0] * xy[:, 0] + K[0, 2] - 0.5).reshape(h, w).astype(np.float32)
        map_y = (K[1, 1] * xy[:, 1] + K[1, 2] - 0.5).reshape(h, w).astype(np.float32)
        img = cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR, borderValue=BACKGROUND)
    yy, xx = np.mgrid[0:h, 0:w]
    img *= (0.75 + 0.25 * xx / w) * gain  # uneven lighting across the view
    if occluder_m > 0:
        # An object on the board: outline of a vertical cylinder's top and base, filled.
        ring = np.linspace(0, 2 * np.pi, 48, endpoint=False)
        circle = np.stack([occluder_m * np.cos(ring), occluder_m * np.sin(ring)], axis=1)
        pts = np.concatenate(
            [
                np.column_stack([circle, np.zeros(48)]),
                np.column_stack([circle, np.full(48, 1.5 * occluder_m)]),
            ]
        )
        uv = project(scene.intrinsics, pose, pts) - 0.5
        hull = cv2.convexHull(uv.astype(np.float32))
        cv2.fillConvexPoly(img, np.round(hull).astype(np.int32), 0.45)
    img = cv2.GaussianBlur(img, (0, 0), blur_sigma)
    img = 255 * np.clip(img, 0, 1) + rng.normal(0, noise_dn, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def orbit_poses(n: int, rng: np.random.Generator, distance: float = 0.5) -> list[Pose]:
    """Cameras around the board at varied elevations and distances (+-15 %), aimed near its
    centre."""
    poses = []
    for i in range(n):
        azimuth = 2 * np.pi * i / n + rng.uniform(-0.1, 0.1)
        elevation = np.radians((50, 62, 74)[i % 3] + rng.uniform(-3, 3))
        eye = (
            distance
            * rng.uniform(0.85, 1.15)
            * np.array(
                [
                    np.cos(elevation) * np.cos(azimuth),
                    np.cos(elevation) * np.sin(azimuth),
                    np.sin(elevation),
                ]
            )
        )
        target = np.array([*rng.uniform(-0.02, 0.02, 2), 0.0])
        poses.append(Pose.look_at(eye, target))
    return poses


@pytest.fixture(scope="session")
def scene() -> Scene:
    spec = BoardSpec.fit_paper("A4")
    texture, extent = board_texture(spec, PX_PER_M)
    intrinsics = Intrinsics("PINHOLE", 1280, 960, (1100.0, 1100.0, 652.3, 471.8))
    return Scene(spec, texture, extent, intrinsics)


@pytest.fixture(scope="session")
def render_view() -> Callable[..., np.ndarray]:
    return render


@pytest.fixture(scope="session")
def orbit() -> Callable[..., list[Pose]]:
    return orbit_poses
