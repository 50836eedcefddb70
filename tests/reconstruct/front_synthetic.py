"""Small synthetic sessions for the front-stage tests: a textured sphere on a black
background, linear NPY frames rendered by ray casting, a manifest with real hashes and
(optionally) the true poses as a COLMAP text model."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
import yaml

from core.files import sha256_file
from core.manifest import FrameRecord, append_manifest
from reconstruct.model.camera import Intrinsics, Pose, write_colmap_text
from reconstruct.model.forward import ggx_lobe
from reconstruct.model.raycast import RayCaster

RADIUS = 0.1
EXPOSURE_S, ISO = 0.02, 200.0


def ring_poses(n: int, distance: float = 0.5) -> list[Pose]:
    """Cameras around the origin at two heights, looking at it."""
    out = []
    for k in range(n):
        a = 2 * np.pi * k / n
        z = 0.2 if k % 2 else -0.1
        out.append(Pose.look_at(np.array([distance * np.cos(a), distance * np.sin(a), z]),
                                np.zeros(3)))
    return out


def render(
    mesh: trimesh.Trimesh, intr: Intrinsics, pose: Pose, gain: np.ndarray, gloss: float = 0.0
) -> np.ndarray:
    """Normalised linear RGB (light at the camera, inverse square, a checker texture), with a
    neutral GGX lobe (alpha 0.2) of reflectance ``gloss`` at normal incidence."""
    caster = RayCaster(mesh.vertices, mesh.faces)
    cols, rows = np.meshgrid(np.arange(intr.width) + 0.5, np.arange(intr.height) + 0.5)
    uv = np.stack([cols.ravel(), rows.ravel()], axis=1)
    dirs = intr.pixel_rays(uv) @ pose.R
    origin = np.broadcast_to(pose.center, dirs.shape)
    tri, dist, _ = caster.first_hit(origin, dirs)
    hit = tri >= 0
    x = origin[hit] + dist[hit, None] * dirs[hit]
    n = mesh.face_normals[tri[hit]]
    irradiance = 0.08 / dist[hit] ** 2
    shade = np.clip(-np.einsum("ij,ij->i", n, dirs[hit]), 0, 1) * irradiance
    theta = np.arctan2(x[:, 1], x[:, 0])
    phi = np.arccos(np.clip(x[:, 2] / np.linalg.norm(x, axis=1), -1, 1))
    albedo = 0.35 + 0.3 * ((np.floor(theta * 12) + np.floor(phi * 12)) % 2)
    to_eye = -dirs[hit]
    lobe = ggx_lobe(n, to_eye, to_eye, 0.2, gloss) if gloss else np.zeros(len(x))
    img = np.zeros((len(uv), 3))
    img[hit] = (shade * albedo + lobe * irradiance)[:, None] * gain
    return img.reshape(intr.height, intr.width, 3).astype(np.float32)


def dented_sphere(depth: float = 0.03) -> trimesh.Trimesh:
    """A sphere with a dimple of ``depth`` metres pushed into its +x side (a concavity no
    silhouette shows)."""
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS)
    v = np.array(mesh.vertices)
    cut = RADIUS - depth / 2
    side = v[:, 0] > cut
    v[side, 0] = cut - (v[side, 0] - cut)
    return trimesh.Trimesh(v, mesh.faces, process=False)


def build_session(
    tmp_path: Path,
    views: int = 12,
    illuminations: tuple[str, ...] = ("white", "red"),
    known_poses: bool = True,
    size: tuple[int, int] = (160, 120),
    extra_yaml: dict | None = None,
    mesh: trimesh.Trimesh | None = None,
    gloss: float = 0.0,
) -> Path:
    """Write a session under ``tmp_path/session`` and return its directory (``gloss``: the
    object's specular reflectance at normal incidence, 0 for none)."""
    root = tmp_path / "session"
    (root / "raw").mkdir(parents=True)
    intr = Intrinsics.pinhole(size[0], size[1], 1.6 * size[0])
    mesh = mesh if mesh is not None else trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)
    gains = {"white": np.array([1.0, 1.0, 1.0]), "red": np.array([0.9, 0.2, 0.1])}
    info = {"rig": "synthetic", "intrinsics": {
        "model": intr.model, "width": intr.width, "height": intr.height,
        "params": list(intr.params)}} | (extra_yaml or {})
    (root / "session.yaml").write_text(yaml.safe_dump(info))
    poses = ring_poses(views)
    frame = 0
    for view, pose in enumerate(poses):
        for name in illuminations:
            img = render(mesh, intr, pose, gains.get(name, np.ones(3)), gloss)
            rel = f"raw/v{view:03d}_{name}.npy"
            np.save(root / rel, img)
            append_manifest(root, FrameRecord(
                frame, view, name, rel, sha256_file(root / rel), EXPOSURE_S, ISO,
                "2026-01-01T00:00:00Z"))
            frame += 1
    if known_poses:
        write_colmap_text(
            root / "poses", {1: intr},
            {v + 1: (1, f"view_{v:04d}", p) for v, p in enumerate(poses)},
        )
    return root
