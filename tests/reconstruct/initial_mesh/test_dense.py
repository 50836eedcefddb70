"""Dense path pieces: silhouettes, carving votes, Poisson clean-up, point thinning."""

from __future__ import annotations

import numpy as np
import trimesh

from reconstruct.initial_mesh.dense.poisson import largest_component, poisson_mesh
from reconstruct.initial_mesh.dense.silhouette import fill_holes, silhouette
from reconstruct.initial_mesh.dense.stereo import thin
from reconstruct.initial_mesh.dense.visual_hull import carve, scene_box
from reconstruct.initial_mesh.stage import MeshConfig
from reconstruct.model.camera import Intrinsics, Pose


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


def test_silhouette_keeps_dark_paint_on_the_outline() -> None:
    """A black patch (3 % reflectance) on the object's rim falls in Otsu's dark class; it
    must still read as object, or the visual hull is carved into the object there."""
    rng = np.random.default_rng(1)
    img = np.abs(rng.normal(0.0, 2e-4, (120, 160)))  # dark background, sensor noise
    img[30:90, 40:120] = 0.5
    img[30:90, 40:70] = 0.03  # the dark paint reaches the outline on the left
    mask = silhouette([np.repeat(img[..., None], 3, axis=2).astype(np.float32)])
    assert mask[30:90, 40:70].mean() > 0.97
    assert mask[:, :35].sum() == 0 and mask[:25].sum() == 0


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


def test_the_default_vote_forgives_a_shadow_cutting_a_limb_in_two_views() -> None:
    """A cast shadow as dark as the background can cut across a limb's outline in two
    neighbouring views (ogre's legs under a point light); PatchMatch's default vote keeps the
    limb."""
    intr = Intrinsics.pinhole(64, 64, 80.0)
    poses = {k: Pose.look_at(np.array([np.cos(a), np.sin(a), 0.3]), np.zeros(3))
             for k, a in enumerate(np.linspace(0, 2 * np.pi, 8, endpoint=False))}
    masks = {k: np.ones((64, 64), bool) for k in poses}
    for view in (0, 1):
        masks[view][:, 24:40] = False  # the shadow's band across the middle
    lo, hi = np.full(3, -0.2), np.full(3, 0.2)
    intrinsics = dict.fromkeys(poses, intr)
    kept, _, _ = carve(masks, intrinsics, poses, lo, hi, 16, 3, MeshConfig().hull_votes())
    cut, _, _ = carve(masks, intrinsics, poses, lo, hi, 16, 3, votes=2)
    assert kept.all() and not cut[8, 8, 8]
    # where the hull is the surface itself, a tighter hull is worth one view's slip only
    assert MeshConfig(method="visual_hull").hull_votes() == 2
    assert MeshConfig(carve_votes=4).hull_votes(hull_is_surface=True) == 4


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


def test_poisson_refuses_an_empty_cloud() -> None:
    import pytest

    from core.errors import RigError

    with pytest.raises(RigError, match="given 0 points"):
        poisson_mesh(np.zeros((0, 3)), np.zeros((0, 3)), 6, 5.0)


def test_thin_averages_per_cell() -> None:
    points = np.array([[0.1, 0.1, 0.1], [0.3, 0.2, 0.1], [1.5, 0.1, 0.1]])
    normals = np.array([[0, 0, 1.0], [0, 1.0, 0], [1.0, 0, 0]])
    p, n = thin(points, normals, 1.0)
    assert len(p) == 2
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    np.testing.assert_allclose(sorted(p[:, 0]), [0.2, 1.5])


def test_scene_box_without_points_spans_the_widest_view() -> None:
    """Views stepping in to 0.7x the distance see less of the object; the box must still hold
    all of it (the carve removes what no silhouette holds, but cannot restore a cut part)."""
    intr = Intrinsics.pinhole(400, 300, 400.0)
    poses = {v: Pose.look_at(d * np.array([np.cos(a), np.sin(a), 0.5]), np.zeros(3))
             for v, (a, d) in enumerate([(0.0, 0.5), (1.5, 0.35), (3.0, 0.5), (4.5, 0.35)])}
    lo, hi = scene_box(dict.fromkeys(poses, intr), poses)
    np.testing.assert_allclose((lo + hi) / 2, 0.0, atol=1e-6)
    far = 0.5 * np.linalg.norm([1, 0, 0.5]) * 300 / 400.0  # the far views' shorter side
    np.testing.assert_allclose(hi - lo, far, rtol=1e-6)


def test_poisson_flares_outside_the_hull_are_pulled_onto_it() -> None:
    from reconstruct.initial_mesh.stage import clip_to_hull

    intr = Intrinsics.pinhole(120, 90, 150.0)
    eyes = [(0.5, 0, 0.1), (-0.5, 0, 0.1), (0, 0.5, 0.1), (0, -0.5, 0.1), (0.1, 0.1, 0.5)]
    poses = {v: Pose.look_at(np.array(e, float), np.zeros(3)) for v, e in enumerate(eyes)}
    rr, cc = np.mgrid[0:90, 0:120]
    pixels = np.stack([cc.ravel() + 0.5, rr.ravel() + 0.5], 1)
    masks = {}
    for v, pose in poses.items():  # silhouettes of a sphere of radius 65 mm
        rays = intr.pixel_rays(pixels) @ pose.R
        along = -(rays @ pose.center)
        miss = np.linalg.norm(pose.center + along[:, None] * rays, axis=1)
        masks[v] = (miss < 0.065).reshape(90, 120)
    hull = trimesh.creation.icosphere(subdivisions=4, radius=0.065)
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.06)
    flare = mesh.vertices[:, 0] > 0.05
    mesh.vertices[flare] *= 1.5  # Poisson's guess over a hole, 30 mm out
    intrinsics = dict.fromkeys(poses, intr)
    bump = mesh.vertices[:, 0] < -0.055
    mesh.vertices[bump] *= 1.2  # outside the hull too, but measured: silhouettes err as well
    measured = mesh.vertices[~flare]  # stereo saw all but the flare
    moved = clip_to_hull(mesh, hull, measured, 0.003, masks, intrinsics, poses, votes=2)
    radius = np.linalg.norm(mesh.vertices, axis=1)
    assert moved == flare.sum() > 0
    assert radius[flare].max() < 0.066
    np.testing.assert_allclose(radius[~flare & ~bump], 0.06)  # inside the hull: stays
    np.testing.assert_allclose(radius[bump], 0.072)  # measured: stays
