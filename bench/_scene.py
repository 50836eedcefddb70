"""Synthetic solver scenes of an exact vertex count: a detailed bumpy sphere painted with the
24 ColorChecker reflectances, cameras on two rings with the light on the camera plate, images
rendered with the one forward model (:mod:`reconstruct.model.render`).
Cached as ``.npz`` so the timed
solve runs in a fresh process that only loads its input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.progress import Progress
from scipy.spatial import ConvexHull

from bench._common import cache_temporary
from calibration.basis import default_basis
from calibration.defaults import (
    colorchecker_reflectances,
)
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.raycast import RayCaster
from reconstruct.model.render import render_image
from reconstruct.optimise.mesh import vertex_normals
from reconstruct.optimise.problem import Frames, Rig
from reconstruct.optimise.synthetic import SyntheticScene, default_responses

RADIUS_M = 0.05
DISTANCE_M = 0.3
LIGHT_OFFSET_M = (0.1, 0.0, 0.0)


def sphere_mesh(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Exactly ``n`` near-uniform vertices on the unit sphere (Fibonacci lattice), triangulated
    by their convex hull, faces oriented outwards."""
    i = np.arange(n) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / n)
    azimuth = np.pi * (1.0 + 5**0.5) * i
    d = np.stack(
        [np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], axis=1
    )
    faces = ConvexHull(d).simplices.astype(np.int64)
    a, b, c = d[faces[:, 0]], d[faces[:, 1]], d[faces[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c) < 0
    faces[inward] = faces[inward][:, ::-1]
    return d, faces


def detailed_shape(d: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Radius × (1 + low-frequency lobes + fine ~1 mm bumps): detail that shading reveals."""
    r = np.ones(len(d))
    for freq, amp in ((2.0, 0.08), (5.0, 0.03), (11.0, 0.012), (23.0, 0.006)):
        k = rng.normal(size=(4, 3)) * freq
        phase = rng.uniform(0, 2 * np.pi, 4)
        r += amp * np.sum(np.sin(d @ k.T + phase), axis=1) / 2.0
    return d * (RADIUS_M * r)[:, None]


def paint(d: np.ndarray, rng: np.random.Generator, regions: int = 48) -> np.ndarray:
    """ColorChecker patch index per vertex: nearest of ``regions`` random centres, patches
    assigned in turn so each of the 24 appears."""
    centres = rng.normal(size=(regions, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    nearest = np.argmax(d @ centres.T, axis=1)
    return np.asarray(rng.permutation(regions) % 24)[nearest]


def ring_poses(n_views: int) -> list[Pose]:
    """Two rings (20° and 45° elevation), cameras looking at the origin from 30 cm."""
    poses = []
    rings = (np.radians(20.0), np.radians(45.0))
    per_ring = int(np.ceil(n_views / 2))
    for v in range(n_views):
        ring, slot = divmod(v, per_ring)
        az = 2 * np.pi * slot / per_ring + ring * np.pi / per_ring
        el = rings[min(ring, 1)]
        eye = DISTANCE_M * np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
        poses.append(Pose.look_at(eye, np.zeros(3)))
    return poses


def build_scene(
    n_vertices: int,
    n_views: int,
    width: int,
    height: int,
    seed: int = 0,
    illuminations: tuple[str, ...] = ("LED1", "LED2"),
    noise: float = 0.0,
) -> SyntheticScene:
    """The scene with rendered images (float32) for the image-sampling path of the cost."""
    rng = np.random.default_rng(seed)
    d, faces = sphere_mesh(n_vertices)
    X = detailed_shape(d, rng)
    basis = default_basis()
    _, cc = colorchecker_reflectances()
    refl = cc[paint(d, rng)]
    alpha = basis.project(refl)
    responses = default_responses(illuminations)
    poses = ring_poses(n_views)
    intr = [Intrinsics.pinhole(width, height, 1.6 * width)] * n_views
    v = np.asarray(LIGHT_OFFSET_M, dtype=float)
    lights = np.stack([p.light_position(v) for p in poses])
    caster = RayCaster(X, faces)
    normals, _ = vertex_normals(X, faces)
    vis = np.zeros((len(X), n_views), dtype=bool)
    n_ill = len(illuminations)
    images = np.zeros((n_views * n_ill, height, width, 3), dtype=np.float32)
    with Progress(transient=True) as progress:
        task = progress.add_task(f"rendering {n_vertices:,}-vertex scene", total=n_views)
        for c, pose in enumerate(poses):
            facing = np.einsum("ij,ij->i", normals, pose.center - X) > 0
            vis[:, c] = facing & ~caster.occluded(X, pose.center, 1e-5, normals)
            for k in range(n_ill):
                img, _ = render_image(
                    X, faces, refl, intr[c], pose, lights[c], responses[k], 1, caster=caster
                )
                images[c * n_ill + k] = img + noise * rng.normal(size=img.shape)
            progress.advance(task)
    frames = Frames(
        np.repeat(np.arange(n_views), n_ill), np.tile(np.arange(n_ill), n_views), images
    )
    return SyntheticScene(
        X, faces, refl, alpha, v, Rig(intr, poses, responses), frames, basis, vis,
        np.zeros((0, 0, 3)),
    )  # fmt: skip


def save_scene(scene: SyntheticScene, path: Path) -> None:
    assert scene.frames.images is not None
    intr = scene.rig.intrinsics[0]
    np.savez(
        path,
        vertices=scene.vertices,
        faces=scene.faces,
        reflectance=scene.reflectance,
        light_offset=scene.light_offset,
        R=np.stack([p.R for p in scene.rig.poses]),
        t=np.stack([p.t for p in scene.rig.poses]),
        size=np.array([intr.width, intr.height]),
        focal=np.array(intr.params[0]),
        responses=scene.rig.responses,
        frame_view=scene.frames.view,
        frame_illumination=scene.frames.illumination,
        images=scene.frames.images,
        visibility=scene.visibility,
    )


def load_scene(path: Path) -> SyntheticScene:
    z = np.load(path)
    basis = default_basis()
    w, h = (int(x) for x in z["size"])
    poses = [Pose(R, t) for R, t in zip(z["R"], z["t"], strict=True)]
    intr = [Intrinsics.pinhole(w, h, float(z["focal"]))] * len(poses)
    refl = z["reflectance"]
    return SyntheticScene(
        z["vertices"], z["faces"], refl, basis.project(refl), z["light_offset"],
        Rig(intr, poses, z["responses"]),
        Frames(z["frame_view"], z["frame_illumination"], z["images"]),
        basis, z["visibility"], np.zeros((0, 0, 3)),
    )  # fmt: skip


def cached_scene(
    cache: Path, n_vertices: int, n_views: int, width: int, height: int, seed: int
) -> Path:
    """Path of the cached scene, building it first when missing."""
    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"scene_{n_vertices}_{n_views}v_{width}x{height}_s{seed}.npz"
    if not path.is_file():
        tmp = cache_temporary(path)
        save_scene(build_scene(n_vertices, n_views, width, height, seed), tmp)
        tmp.replace(path)
    return path
