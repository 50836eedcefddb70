"""PatchMatch stereo on a textured plane rendered analytically from five views."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.ndimage import map_coordinates

from reconstruct.initial_mesh.dense.patchmatch import (
    PatchMatchConfig,
    ViewDepth,
    depth_at,
    fuse,
    patchmatch_points,
    patchmatch_view,
    scaled,
    source_views,
    undistorted,
    window_offsets,
)
from reconstruct.initial_mesh.dense.plane_cost import texture_map
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.raycast import RayCaster

WIDTH, HEIGHT, FOCAL = 200, 150, 400.0


def _texture(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0.2, 1.0, (40, 40))


def _render(intr: Intrinsics, pose: Pose, tex: np.ndarray, gain: float, ramp: float) -> np.ndarray:
    """The plane z = 0 (texture over [-0.1, 0.1]^2 m) seen by a camera; a gain and a shading
    ramp per image stand for a lamp that moves with the camera."""
    rr, cc = np.mgrid[0:intr.height, 0:intr.width]
    uv = np.stack([cc.ravel() + 0.5, rr.ravel() + 0.5], 1)
    d = intr.pixel_rays(uv) @ pose.R
    t = -pose.center[2] / d[:, 2]
    x = pose.center + t[:, None] * d
    coords = (x[:, :2] + 0.1) / 0.2 * (tex.shape[0] - 1)
    value = map_coordinates(tex, [coords[:, 1], coords[:, 0]], order=3, mode="nearest")
    shade = 1.0 + ramp * x[:, 0] / 0.1
    return (gain * shade * value).reshape(intr.height, intr.width).astype(np.float32)


@pytest.fixture(scope="module")
def plane_scene() -> dict:
    intr = Intrinsics.pinhole(WIDTH, HEIGHT, FOCAL)
    poses, images = {}, {}
    for v, (az, el) in enumerate([(0, 70), (30, 60), (-30, 60), (90, 65), (-90, 65)]):
        a, e = np.radians(az), np.radians(el)
        eye = 0.5 * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        poses[v] = Pose.look_at(eye, np.zeros(3))
        illum = [_render(intr, poses[v], _texture(s), 1.0 + 0.3 * v, 0.2 * (v - 2))
                 for s in (1, 2)]
        images[v] = np.stack(illum, axis=-1)
    hull = trimesh.creation.box(extents=(0.2, 0.2, 0.02))  # top face 1 cm above the plane
    masks = {v: np.ones((HEIGHT, WIDTH), bool) for v in poses}
    return {"intr": intr, "poses": poses, "images": images, "hull": hull, "masks": masks}


def test_scaled_intrinsics_follow_the_resized_image() -> None:
    intr = Intrinsics("OPENCV", 640, 480, (800.0, 790.0, 320.5, 240.2, 0.1, 0.0, 0.0, 0.0))
    half = scaled(intr, 0.5)
    assert (half.width, half.height) == (320, 240)
    assert half.params[:4] == pytest.approx((400.0, 395.0, 160.25, 120.1))
    assert half.params[4] == pytest.approx(0.1)  # distortion is in normalised units


def test_depth_of_a_textured_plane_under_changing_light(plane_scene: dict) -> None:
    s = plane_scene
    conf = PatchMatchConfig(scale=1.0, iterations=5, sources=4, top_k=2)
    caster = RayCaster(s["hull"].vertices, s["hull"].faces)
    sources = [(s["images"][o], s["intr"], s["poses"][o]) for o in (1, 2, 3, 4)]
    vd = patchmatch_view(s["images"][0], s["masks"][0], s["intr"], s["poses"][0], sources,
                         caster, 0.03, conf)
    rows, cols = np.nonzero(np.isfinite(vd.distance) & (vd.cost < conf.cost_max))
    assert len(rows) > 0.5 * WIDTH * HEIGHT
    rays = s["intr"].pixel_rays(np.stack([cols + 0.5, rows + 0.5], 1)) @ s["poses"][0].R
    truth = -s["poses"][0].center[2] / rays[:, 2]
    error = np.abs(vd.distance[rows, cols] - truth)
    pixel_m = 0.5 / FOCAL
    assert np.median(error) < 0.5 * pixel_m  # the hull top is 8 pixels of depth in front
    normals = vd.normal[rows, cols] @ s["poses"][0].R
    assert np.median(normals[:, 2]) > 0.99  # the plane faces +z


def test_fused_points_lie_on_the_plane(plane_scene: dict) -> None:
    s = plane_scene
    conf = PatchMatchConfig(scale=0.5, iterations=4, sources=4, top_k=2, min_consistent=2)
    intrinsics = dict.fromkeys(s["poses"], s["intr"])
    dense = patchmatch_points(
        s["hull"].vertices, s["hull"].faces, s["images"], s["masks"], intrinsics, s["poses"], conf
    )
    points, normals = dense.points, dense.normals
    assert dense.stats["patchmatch_points"] == len(points) > 1000
    assert set(dense.maps) == set(s["poses"])
    assert np.percentile(np.abs(points[:, 2]), 90) < 0.5 / (FOCAL * 0.5)
    assert np.median(normals[:, 2]) > 0.99


def test_source_views_skip_views_without_parallax() -> None:
    poses = {v: Pose.look_at(0.5 * np.array([np.cos(a), np.sin(a), 0.3]), np.zeros(3))
             for v, a in enumerate(np.radians([0, 1, 20, 40, 90]))}
    near = source_views(poses, np.zeros(3), 3, min_deg=4.0, max_deg=45.0)
    assert near[0] == [2, 3]  # 1° is no parallax, 90° is too far to match windows


def test_undistorted_images_follow_the_pinhole_projection() -> None:
    """A point seen at p_d by a RADIAL camera lies at the pinhole projection in the undistorted
    image: what the matching kernel assumes."""
    intr = Intrinsics("RADIAL", 320, 240, (300.0, 160.5, 120.2, -0.2, 0.05))
    rr, cc = np.mgrid[0:240, 0:320].astype(float)
    image = (np.sin(cc / 9.0) + np.cos(rr / 7.0))[..., None]
    flat, mask, pinhole = undistorted(image, np.ones((240, 320), bool), intr)
    assert pinhole.model == "PINHOLE" and pinhole.params == pytest.approx((300, 300, 160.5, 120.2))
    points = np.array([[0.1, -0.05, 1.0], [-0.2, 0.1, 1.0], [0.15, 0.15, 1.0]])
    p_d = intr.project_camera(points)
    p_u = pinhole.project_camera(points)
    # pixel-corner coordinates -> array indices (centre of the top-left pixel at 0.5)
    original = map_coordinates(image[..., 0], [p_d[:, 1] - 0.5, p_d[:, 0] - 0.5], order=1)
    seen = map_coordinates(flat[..., 0], [p_u[:, 1] - 0.5, p_u[:, 0] - 0.5], order=1)
    np.testing.assert_allclose(seen, original, atol=0.02)
    assert mask[120, 160]


def test_shading_ramps_are_not_texture() -> None:
    """The lamp rides on the camera, so smooth shading changes slope from view to view; a
    window holding only a ramp of intensity has no texture to match, a painted edge has."""
    rows, cols = np.mgrid[0:40, 0:40].astype(float)
    ramp = 0.3 + 0.01 * cols + 0.004 * rows
    edge = ramp + 0.2 * (cols > 20)
    image = np.stack([ramp, edge], axis=-1)
    dr, dc = window_offsets(PatchMatchConfig())
    texture = texture_map(image, np.ones((40, 40), bool), dr, dc)
    assert texture[10, 10] < 1e-6 < PatchMatchConfig().min_texture < texture[10, 20]
    flat = np.stack([ramp, ramp], axis=-1)
    assert texture_map(flat, np.ones((40, 40), bool), dr, dc)[20, 20] < 1e-6


def _plane_maps(plane_scene: dict, bias_m: dict[int, float]) -> dict[int, ViewDepth]:
    """Depth maps of the plane z = 0 at every pixel of each view in ``bias_m``, read that much
    too far along the rays."""
    intr = plane_scene["intr"]
    rr, cc = np.mgrid[0:HEIGHT, 0:WIDTH]
    pixels = np.stack([cc.ravel() + 0.5, rr.ravel() + 0.5], 1)
    maps = {}
    for v, bias in bias_m.items():
        pose = plane_scene["poses"][v]
        rays = intr.pixel_rays(pixels) @ pose.R
        distance = (-pose.center[2] / rays[:, 2] + bias).reshape(HEIGHT, WIDTH)
        normal = np.broadcast_to(pose.R @ np.array([0.0, 0.0, 1.0]), (HEIGHT, WIDTH, 3))
        maps[v] = ViewDepth(distance, np.array(normal), np.zeros((HEIGHT, WIDTH)), intr)
    return maps


def test_fusion_averages_the_views_that_confirm_a_point(plane_scene: dict) -> None:
    """Two views read the plane z = 0; view 1 reads it 2 mm too far along its rays. Each
    fused point is the mean of both readings, so every point lies between the two."""
    poses = {v: plane_scene["poses"][v] for v in (0, 1)}
    maps = _plane_maps(plane_scene, {0: 0.0, 1: 0.002})
    points, normals, stats = fuse(maps, poses, {0: [1], 1: [0]}, PatchMatchConfig(min_consistent=1))
    assert stats["patchmatch_points"] > 0.3 * WIDTH * HEIGHT
    below = -points[:, 2]  # view 1's reading lies 2 mm * sin(elevation) below the plane
    assert np.percentile(below, 5) > 0.0006 and np.percentile(below, 95) < 0.0011
    assert np.median(normals[:, 2]) > 0.999


def test_exact_depths_confirm_each_other_wherever_the_point_falls_in_a_pixel(
    plane_scene: dict,
) -> None:
    """The check reads the other view's depth where the point projects, not at the nearest
    pixel's centre: two exact readings agree to a tenth of a pixel everywhere they overlap."""
    poses = {v: plane_scene["poses"][v] for v in (0, 1)}
    maps = _plane_maps(plane_scene, {0: 0.0, 1: 0.0})
    conf = PatchMatchConfig(min_consistent=1, consistency_px=0.1)
    points, _, stats = fuse(maps, poses, {0: [1], 1: [0]}, conf)
    rr, cc = np.mgrid[0:HEIGHT, 0:WIDTH]
    rays = plane_scene["intr"].pixel_rays(np.stack([cc.ravel() + 0.5, rr.ravel() + 0.5], 1))
    seen_by_both = 0
    for v, other in ((0, 1), (1, 0)):
        world = poses[v].to_world(rays * maps[v].distance.reshape(-1, 1))
        uv = plane_scene["intr"].project_camera(poses[other].to_camera(world))
        # a pixel's margin inside the border, where all four bilinear taps exist
        seen_by_both += np.count_nonzero(
            (uv[:, 0] > 1) & (uv[:, 0] < WIDTH - 1) & (uv[:, 1] > 1) & (uv[:, 1] < HEIGHT - 1))
    assert stats["patchmatch_points"] >= seen_by_both > 0.3 * 2 * WIDTH * HEIGHT
    # on the plane to a micrometre: a bilinear reading of distance along a ray is not exact
    # on a plane, and the few points within half a pixel of the other view's border read it
    # clamped
    assert np.percentile(np.abs(points[:, 2]), 99) < 1e-6


def test_depth_at_reads_between_pixel_centres() -> None:
    import doctest

    import reconstruct.initial_mesh.dense.patchmatch as module

    assert doctest.testmod(module).failed == 0
    distance = np.arange(12.0).reshape(3, 4)  # linear in rows and columns: bilinear is exact
    uv = np.array([[0.5, 0.5], [1.25, 2.0], [3.5, 2.5], [2.0, 1.75]])
    np.testing.assert_allclose(depth_at(distance, uv), [0.0, 6.75, 11.0, 6.5])
