"""The forward model, ray casting and image rendering against known answers."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import RigError
from reconstruct.model import forward, render
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.raycast import RayCaster

N_L = 31


def plane(size: float, z: float = 0.0, n: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A square of side ``size`` at height ``z`` facing +z, split into 2·n² triangles."""
    g = np.linspace(-size / 2, size / 2, n + 1)
    xx, yy = np.meshgrid(g, g, indexing="ij")
    v = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)], axis=1)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    a, b, c, d = i, i + (n + 1), i + (n + 2), i + 1
    f = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    return v, f


def test_response_matrix_is_ct_diag_l() -> None:
    rng = np.random.default_rng(0)
    C, L, r = rng.random((N_L, 3)), rng.random(N_L), rng.random(N_L)
    M = forward.response_matrix(C, L)
    assert M.shape == (3, N_L)
    np.testing.assert_allclose(M @ r, [np.sum(C[:, k] * L * r) for k in range(3)])
    with pytest.raises(RigError, match="spectral grid"):
        forward.response_matrix(C, L[:-1])


def test_shading_tilted_plane_and_inverse_square() -> None:
    theta = np.deg2rad([0.0, 30.0, 60.0, 89.0])
    normals = np.stack([np.sin(theta), np.zeros(4), np.cos(theta)], axis=1)
    points = np.zeros((4, 3))
    s = forward.shading(points, normals, np.array([0.0, 0.0, 0.5]))
    np.testing.assert_allclose(s, np.cos(theta) / 0.25)
    # Inverse square law: twice the distance, a quarter of the light.
    near = forward.shading(points[:1], normals[:1], np.array([0.0, 0.0, 0.3]))
    far = forward.shading(points[:1], normals[:1], np.array([0.0, 0.0, 0.6]))
    np.testing.assert_allclose(near / far, 4.0)
    # Light behind the surface (and a light exactly at the point) gives no shading.
    back = forward.shading(points[:2], normals[:2], np.array([[0, 0, -0.5], [0, 0, 0.0]]))
    np.testing.assert_array_equal(back, [0.0, 0.0])
    # Off-axis light: (p - x)·n / |p - x|^3 with the full 3-D distance.
    s = forward.shading(np.array([[0.1, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]]), [0, 0, 0.2])
    np.testing.assert_allclose(s, 0.2 / np.hypot(0.1, 0.2) ** 3)


def test_render_values_mask_and_linearity() -> None:
    rng = np.random.default_rng(1)
    R, M = rng.random((5, N_L)), rng.random((3, N_L))
    s = rng.random(5)
    mask = np.array([True, False, True, True, False])
    y = forward.render_values(R, s, M, mask)
    np.testing.assert_allclose(y[mask], (s[mask, None] * R[mask]) @ M.T)
    np.testing.assert_array_equal(y[~mask], 0.0)


def test_first_hit_distance_and_barycentrics() -> None:
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    rc = RayCaster(v, np.array([[0, 1, 2]]))
    o = np.array([[0.2, 0.3, 2.0], [0.9, 0.9, 2.0], [0.5, 0.1, -1.0]])
    d = np.array([[0, 0, -3.0], [0, 0, -1.0], [0, 0, 1.0]])
    tri, dist, bary = rc.first_hit(o, d)
    np.testing.assert_array_equal(tri, [0, -1, 0])
    np.testing.assert_allclose(dist[[0, 2]], [2.0, 1.0])
    assert np.isinf(dist[1])
    np.testing.assert_allclose(bary[0], [0.5, 0.2, 0.3])
    np.testing.assert_allclose(bary[2], [0.4, 0.5, 0.1])
    np.testing.assert_allclose(bary[[0, 2]] @ v, [[0.2, 0.3, 0], [0.5, 0.1, 0]], atol=1e-12)


def test_occluded_segments() -> None:
    ground, gf = plane(1.0, 0.0, n=4)
    block, bf = plane(0.1, 0.2)
    v = np.vstack([ground, block])
    f = np.vstack([gf, bf + len(ground)])
    rc = RayCaster(v, f)
    pts = np.array([[0.0, 0, 0], [0.3, 0.3, 0], [0.0, 0, 0.3]])
    light = np.array([0.0, 0.0, 1.0])
    # Under the blocker: shadowed; beside it: lit; above it: lit (segment ends before it).
    np.testing.assert_array_equal(rc.occluded(pts, light), [True, False, False])
    # Points on mesh vertices do not occlude themselves, with or without normals.
    on = ground[[0, 7, 24]]
    assert not rc.occluded(on, on + [0.01, 0.02, 1.0]).any()
    assert not rc.occluded(on, on + [0.01, 0.02, 1.0], normals=np.tile([0, 0, 1.0], (3, 1))).any()
    # A target below the ground is blocked by it.
    assert rc.occluded(np.array([0.3, 0.3, 0.05]), np.array([0.3, 0.3, -0.5]))[0]


def _plane_view(dist: float) -> tuple[Intrinsics, Pose]:
    intr = Intrinsics.pinhole(64, 48, 80.0)
    return intr, Pose.look_at(np.array([0.0, 0.0, dist]), np.zeros(3), up=(0.0, 1.0, 0.0))


def test_render_plane_matches_analytic_model() -> None:
    v, f = plane(2.0, 0.0, n=6)
    rng = np.random.default_rng(2)
    refl = np.tile(rng.random(N_L), (len(v), 1))
    M = rng.random((3, N_L))
    intr, pose = _plane_view(0.5)
    light = np.array([0.05, -0.02, 0.45])
    img, cov = render.render_image(v, f, refl, intr, pose, light, M, supersample=2)
    assert img.shape == (48, 64, 3) and cov.shape == (48, 64)
    np.testing.assert_array_equal(cov, 1.0)
    # Analytic: intersect each sub-pixel ray with z = 0 by hand, shade, average.
    ss = 2
    r, c = np.mgrid[0 : 48 * ss, 0 : 64 * ss]
    uv = np.stack([(c.ravel() + 0.5) / ss, (r.ravel() + 0.5) / ss], axis=1)
    d = intr.pixel_rays(uv) @ pose.R
    x = pose.center + (-pose.center[2] / d[:, 2])[:, None] * d
    s = forward.shading(x, np.tile([0, 0, 1.0], (len(x), 1)), light)
    y = forward.render_values(np.tile(refl[0], (len(x), 1)), s, M)
    expect = y.reshape(48, ss, 64, ss, 3).mean(axis=(1, 3))
    np.testing.assert_allclose(img, expect, rtol=1e-9)
    # Flat normals are the same on a plane.
    flat, _ = render.render_image(v, f, refl, intr, pose, light, M, normals="flat")
    np.testing.assert_allclose(flat, img, rtol=1e-9)


def test_render_shadow_where_light_is_occluded() -> None:
    ground, gf = plane(1.0, 0.0, n=2)
    block, bf = plane(0.04, 0.1)
    v = np.vstack([ground, block])
    f = np.vstack([gf, bf + len(ground)])
    refl = np.full((len(v), N_L), 0.5)
    M = np.ones((3, N_L))
    intr, pose = _plane_view(0.5)
    # Light far to the side so the blocker's shadow falls beside it in the image.
    light = np.array([0.3, 0.0, 0.4])
    img, _ = render.render_image(v, f, refl, intr, pose, light, M, supersample=1)
    # Shadow of the blocker's centre on the ground: from the light through (0,0,0.1) to z=0.
    k = light[2] / (light[2] - 0.1)
    shadow = light + k * (np.array([0, 0, 0.1]) - light)
    uv = intr.project_camera(pose.to_camera(shadow[None]))[0]
    col, row = int(uv[0]), int(uv[1])
    assert img[row, col].max() == 0.0
    # The mirror point on the other side of the blocker is lit.
    mirror = intr.project_camera(pose.to_camera(-shadow[None] * [1, 1, 0]))[0]
    assert img[int(mirror[1]), int(mirror[0])].min() > 0.0


def test_projector_lights_only_its_pattern() -> None:
    v, f = plane(2.0, 0.0, n=2)
    refl = np.full((len(v), N_L), 0.5)
    intr, pose = _plane_view(0.5)
    proj_intr = Intrinsics.pinhole(32, 24, 40.0)
    proj_pose = Pose.look_at(np.array([0.0, 0.0, 0.5]), np.zeros(3), up=(0.0, 1.0, 0.0))
    pattern = np.zeros((24, 32, 3))
    pattern[:, :16, 0] = 1.0  # left half red primary only
    resp = [np.eye(3)[k][:, None] * np.ones((1, N_L)) for k in range(3)]
    caster = RayCaster(v, f)
    hits = render.trace_view(caster, intr, pose, 1)
    w = render.projector_weights(caster, hits, pattern, proj_intr, proj_pose)
    img = render.shade(hits, [(w[:, k], resp[k]) for k in range(3)], refl)
    # Camera and projector share the pose and the image is twice the size: left half red.
    assert img[:, :30, 0].min() > 0 and img[:, 34:].max() == 0.0
    assert img[..., 1:].max() == 0.0
    # Red value = s * sum(r) for the red response row at the image centre-left.
    s = forward.shading(np.zeros((1, 3)), np.array([[0, 0, 1.0]]), [0, 0, 0.5])[0]
    assert img[24, 31, 0] == pytest.approx(s * 0.5 * N_L, rel=1e-3)


def test_missing_embree_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    import trimesh.ray

    monkeypatch.setattr(trimesh.ray, "has_embree", False)
    with pytest.raises(RigError, match="embreex"):
        RayCaster(*plane(1.0))


def test_half_angles() -> None:
    points = np.zeros((3, 3))
    normals = np.array([[0.0, 0.0, 1.0]] * 3)
    lights = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 0.0, 1.0]])
    cameras = np.array([[0.0, 0.0, 2.0], [-1.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    got = np.degrees(forward.half_angles(points, normals, lights, cameras))
    assert np.allclose(got, [0.0, 0.0, 22.5])
