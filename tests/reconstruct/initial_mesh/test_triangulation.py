"""Triangulation, rejection and projector resection on synthetic correspondences."""

from __future__ import annotations

import numpy as np
import pytest

from reconstruct.initial_mesh.point_cloud import oriented_normals
from reconstruct.initial_mesh.projector_pose import light_positions, projector_pose, resect
from reconstruct.initial_mesh.triangulation import Observer, check_points, triangulate
from reconstruct.model.camera import Intrinsics, Pose, project

RADIUS = 0.07


def _sphere_hits(intr: Intrinsics, pose: Pose) -> np.ndarray:
    """Where each projector pixel centre's ray meets a sphere at the origin (NaN: misses)."""
    v, u = np.mgrid[0 : intr.height, 0 : intr.width]
    uv = np.stack([u.ravel() + 0.5, v.ravel() + 0.5], axis=1)
    d = intr.pixel_rays(uv) @ pose.R  # world directions
    c = pose.center
    b = d @ c
    disc = b * b - (c @ c - RADIUS**2)
    s = -b - np.sqrt(np.where(disc >= 0, disc, np.nan))
    return c + s[:, None] * d, uv


def _scene(seed: int = 0):
    rng = np.random.default_rng(seed)
    cam = Intrinsics.pinhole(320, 240, 600.0)
    poses = [
        Pose.look_at(0.5 * np.array([np.cos(a), np.sin(a), 0.3]), np.zeros(3))
        for a in np.radians([-70.0, -90.0, -110.0])
    ]
    proj_intr = Intrinsics.pinhole(128, 96, 220.0)
    proj_pose = Pose.look_at(np.array([0.1, -0.45, 0.2]), np.zeros(3))
    points, proj_uv = _sphere_hits(proj_intr, proj_pose)
    hit = np.all(np.isfinite(points), axis=1)
    points, proj_uv = points[hit], proj_uv[hit]
    obs = np.full((len(points), len(poses), 2), np.nan)
    for k, pose in enumerate(poses):
        facing = np.einsum("ij,ij->i", points, pose.center - points) > 0  # sphere normal = X/r
        uv = project(cam, pose, points) + rng.normal(0, 0.2, (len(points), 2))
        obs[facing & cam.in_image(uv), k] = uv[facing & cam.in_image(uv)]
    return cam, poses, proj_intr, proj_pose, points, proj_uv, obs


def test_dlt_recovers_points_and_rejects_outliers() -> None:
    cam, poses, _, _, truth, _, obs = _scene()
    seen2 = np.sum(~np.isnan(obs[:, :, 0]), axis=1) >= 2
    truth, obs = truth[seen2], obs[seen2]
    bad = np.arange(0, len(obs), 50)
    obs[bad, 0] += 15.0  # gross mismatches in the first view
    observers = [Observer(cam, p, 2.0) for p in poses]
    points = triangulate(obs, observers)
    ok, rms = check_points(points, obs, observers, min_angle_deg=2.0)
    err = np.linalg.norm(points - truth, axis=1)
    assert ok.mean() > 0.9
    assert not ok[bad][~np.isnan(obs[bad, 0, 0])].any()
    assert np.median(err[ok]) < 3e-4 and np.percentile(err[ok], 99) < 2e-3
    assert np.median(rms[ok]) < 0.5


def test_narrow_baseline_is_rejected() -> None:
    cam, _, _, _, truth, _, _ = _scene()
    close = [Pose.look_at(np.array([x, -0.5, 0.0]), np.zeros(3)) for x in (0.0, 0.005)]
    obs = np.stack([project(cam, p, truth) for p in close], axis=1)
    ok, _ = check_points(triangulate(obs, [Observer(cam, p, 2.0) for p in close]), obs,
                         [Observer(cam, p, 2.0) for p in close], min_angle_deg=2.0)
    assert not ok.any()


@pytest.mark.parametrize("known_focal", [True, False])
def test_projector_pose_by_resection(known_focal: bool) -> None:
    _, _, proj_intr, proj_pose, truth, proj_uv, _ = _scene()
    rng = np.random.default_rng(1)
    noisy = truth + rng.normal(0, 2e-4, truth.shape)
    focal = 220.0 if known_focal else None
    intr, pose, inliers = projector_pose(noisy, proj_uv, (128, 96), focal, 2.0)
    assert np.linalg.norm(pose.center - proj_pose.center) < 5e-3
    assert abs(intr.params[0] - 220.0) / 220.0 < 0.03
    assert inliers > 0.9 * len(truth)
    K, exact = resect(truth, proj_uv)
    assert np.allclose(exact.center, proj_pose.center, atol=1e-6)
    assert np.allclose(K, proj_intr.K, atol=1e-4)
    lights = light_positions({3: "a", 4: "a", 5: "b"}, {"a": pose})
    assert set(lights) == {3, 4} and np.allclose(lights[3], pose.center)


def test_normals_face_the_cameras() -> None:
    _, poses, _, _, truth, _, _ = _scene()
    towards = poses[1].center - truth
    normals = oriented_normals(truth, towards, 12)
    radial = truth / np.linalg.norm(truth, axis=1, keepdims=True)
    assert np.median(np.einsum("ij,ij->i", normals, radial)) > 0.99


def test_block_centroids_merge_finer_codes() -> None:
    from reconstruct.initial_mesh.structured_light import GrayDecoding
    from reconstruct.initial_mesh.triangulation import block_centroids

    col = np.array([[0, 1, 2, 3], [0, 1, 2, 3]])
    row = np.array([[0, 0, 1, 1], [1, 1, 0, 0]])
    valid = np.ones_like(col, bool)
    valid[1, 3] = False
    dec = GrayDecoding(col, row, valid, 1, 1, (4, 2))
    fine = block_centroids(dec)
    assert len(fine["keys"]) == 7
    coarse = block_centroids(dec, (2, 2))  # 2 x 1 blocks: columns {0,1} and {2,3}
    assert list(coarse["keys"]) == [0, 1] and list(coarse["counts"]) == [4, 3]
    assert np.allclose(coarse["xy"], [[1.0, 1.0], [(2.5 + 3.5 + 2.5) / 3, (0.5 + 0.5 + 1.5) / 3]])
