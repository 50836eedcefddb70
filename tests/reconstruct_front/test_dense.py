"""Dense path pieces: silhouettes, carving votes, Poisson clean-up, point thinning."""

from __future__ import annotations

import numpy as np
import trimesh

from reconstruct.camera import Intrinsics, Pose
from reconstruct.dense.poisson import largest_component, poisson_mesh
from reconstruct.dense.silhouette import fill_holes, silhouette
from reconstruct.dense.stereo import thin
from reconstruct.dense.visual_hull import carve


def test_silhouette_keeps_dark_limb_and_fills_holes() -> None:
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:80, 0:80]
    r = np.hypot(xx - 40, yy - 40)
    disc = r < 25
    shade = np.clip(np.sqrt(np.maximum(1 - (r / 25) ** 2, 0)), 0, 1)  # dark towards the limb
    img = np.where(disc, 0.5 * shade, 0.0)[..., None] * np.ones(3)
    img[(np.hypot(xx - 40, yy - 40) < 5)] = 0.0  # a black spot inside
    img += rng.normal(0, 1e-4, img.shape)
    mask = silhouette([img.astype(np.float32)])
    assert mask[40, 40]  # hole filled
    assert (mask & ~disc).sum() == 0
    assert (disc & ~mask).sum() < 0.04 * disc.sum()  # only the very rim is lost
    assert fill_holes(np.pad(np.ones((3, 3), bool), 2)).sum() == 9


def test_carving_votes_forgive_one_wrong_silhouette() -> None:
    intr = Intrinsics.pinhole(64, 64, 80.0)
    poses = {k: Pose.look_at(np.array([np.cos(a), np.sin(a), 0.3]), np.zeros(3))
             for k, a in enumerate(np.linspace(0, 2 * np.pi, 8, endpoint=False))}
    masks = {k: np.ones((64, 64), bool) for k in poses}
    masks[0][:] = False  # one view sees nothing (e.g. its frame is all in shadow)
    lo, hi = np.full(3, -0.2), np.full(3, 0.2)
    strict, _, _ = carve(masks, {k: intr for k in poses}, poses, lo, hi, 16, 3, votes=1)
    lenient, _, _ = carve(masks, {k: intr for k in poses}, poses, lo, hi, 16, 3, votes=2)
    assert lenient.all() and not strict[8, 8, 8]


def test_poisson_keeps_the_largest_piece() -> None:
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    mesh = poisson_mesh(np.asarray(sphere.vertices), np.asarray(sphere.vertex_normals), 6, 0.0, 1)
    r = np.linalg.norm(mesh.vertices, axis=1)
    assert mesh.is_watertight and abs(r.mean() - 1.0) < 0.03
    box = trimesh.creation.box()
    box.apply_translation([10, 0, 0])
    both = trimesh.Trimesh(np.vstack([sphere.vertices, box.vertices]),
                           np.vstack([sphere.faces, box.faces + len(sphere.vertices)]))
    assert len(largest_component(both).faces) == len(sphere.faces)


def test_thin_averages_per_cell() -> None:
    points = np.array([[0.1, 0.1, 0.1], [0.3, 0.2, 0.1], [1.5, 0.1, 0.1]])
    normals = np.array([[0, 0, 1.0], [0, 1.0, 0], [1.0, 0, 0]])
    p, n = thin(points, normals, 1.0)
    assert len(p) == 2
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    np.testing.assert_allclose(sorted(p[:, 0]), [0.2, 1.5])
