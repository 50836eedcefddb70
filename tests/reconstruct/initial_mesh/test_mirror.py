"""Depth-map pixels near the lamp's mirror direction, found from a surface and dropped."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from reconstruct.initial_mesh.dense.mirror import without_near_mirror
from reconstruct.initial_mesh.dense.patchmatch import ViewDepth
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.forward import half_angles
from reconstruct.model.raycast import RayCaster

RADIUS = 0.1


@pytest.fixture(scope="module")
def sphere_view() -> tuple[ViewDepth, Pose, trimesh.Trimesh]:
    """A sphere seen from 0.5 m with every pixel's true depth (NaN off the sphere)."""
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS)
    caster = RayCaster(np.asarray(sphere.vertices), np.asarray(sphere.faces))
    intr = Intrinsics.pinhole(120, 120, 300.0)
    pose = Pose.look_at(np.array([0.0, 0.0, 0.5]), np.zeros(3))
    rr, cc = np.mgrid[0:120, 0:120]
    rays = intr.pixel_rays(np.stack([cc.ravel() + 0.5, rr.ravel() + 0.5], 1)) @ pose.R
    _, distance, _ = caster.first_hit(np.broadcast_to(pose.center, rays.shape), rays)
    depth = np.where(np.isfinite(distance), distance, np.nan).reshape(120, 120)
    return ViewDepth(depth, np.zeros((120, 120, 3)), np.zeros((120, 120)), intr), pose, sphere


def _sphere_half_angles(vd: ViewDepth, pose: Pose, light: np.ndarray) -> np.ndarray:
    """Each pixel's half-angle (degrees) from the sphere's exact normals (NaN off it)."""
    rr, cc = np.mgrid[0:120, 0:120]
    rays = vd.intrinsics.pixel_rays(np.stack([cc.ravel() + 0.5, rr.ravel() + 0.5], 1)) @ pose.R
    x = pose.center + rays * vd.distance.reshape(-1, 1)
    lights, cameras = np.broadcast_to(light, x.shape), np.broadcast_to(pose.center, x.shape)
    return np.degrees(half_angles(x, x / RADIUS, lights, cameras)).reshape(120, 120)


def test_pixels_within_the_angle_of_the_mirror_direction_are_dropped(sphere_view) -> None:
    vd, pose, sphere = sphere_view
    offset = np.array([0.1, 0.0, 0.0])  # the lamp 10 cm beside the lens
    maps, dropped = without_near_mirror({0: vd}, {0: pose}, offset, sphere, 20.0)
    kept = np.isfinite(maps[0].distance)
    angle = _sphere_half_angles(vd, pose, pose.light_position(offset))
    on_sphere = np.isfinite(vd.distance)
    assert dropped == int((on_sphere & ~kept).sum()) > 50
    # the faceted sphere's normals differ from the exact ones by under a degree
    assert np.all(~kept[on_sphere & (angle < 19.0)])
    assert np.all(kept[on_sphere & (angle > 21.0)])
    assert np.array_equal(maps[0].distance[kept], vd.distance[kept])  # the rest untouched
    assert np.isfinite(vd.distance).sum() == on_sphere.sum()  # the input map is not changed
    # the highlight sits between the lens and the lamp, not at the image centre
    cols = np.nonzero(~kept & on_sphere)[1]
    assert abs(cols.mean() + 0.5 - vd.intrinsics.K[0, 2]) > 3


def test_nothing_is_dropped_at_zero_degrees_or_where_rays_miss_the_surface(sphere_view) -> None:
    vd, pose, sphere = sphere_view
    maps, dropped = without_near_mirror({0: vd}, {0: pose}, np.zeros(3), sphere, 0.0)
    assert dropped == 0
    assert np.array_equal(np.isfinite(maps[0].distance), np.isfinite(vd.distance))
    far = trimesh.creation.box(extents=(0.05, 0.05, 0.05))
    far.apply_translation([1.0, 0.0, 0.0])  # out of the view: every ray misses it
    maps, dropped = without_near_mirror({0: vd}, {0: pose}, np.zeros(3), far, 45.0)
    assert dropped == 0


def test_a_pit_the_highlight_left_in_the_surface_is_judged_by_the_normals_around_it(
    sphere_view,
) -> None:
    """PatchMatch puts a moving highlight behind a convex glaze: the first surface has a pit
    there, whose walls tilt away from the mirror direction. The normals averaged over a patch
    wider than the pit are the sphere's, so the highlight's pixels are dropped anyway."""
    vd, pose, _ = sphere_view
    offset = np.array([0.1, 0.0, 0.0])
    light = pose.light_position(offset)
    mirror = pose.center / np.linalg.norm(pose.center) + light / np.linalg.norm(light)
    mirror /= np.linalg.norm(mirror)
    pitted = trimesh.creation.icosphere(subdivisions=6, radius=RADIUS)
    unit = np.asarray(pitted.vertices) / RADIUS
    s = np.arccos(np.clip(unit @ mirror, -1.0, 1.0)) / np.radians(8.0)  # a pit 28 mm across
    depth = np.where(s < 1.0, 0.016 * (1.0 - s**2) ** 2, 0.0)
    pitted = trimesh.Trimesh(unit * (RADIUS - depth)[:, None], pitted.faces, process=False)
    angle = _sphere_half_angles(vd, pose, light)
    on_sphere = np.isfinite(vd.distance)
    highlight, far = on_sphere & (angle < 15.0), on_sphere & (angle > 40.0)

    inputs = {0: vd}, {0: pose}, offset, pitted, 20.0
    walls, _ = without_near_mirror(*inputs, average_fraction=0.0)
    assert np.isfinite(walls[0].distance[highlight]).mean() > 0.25  # by the pit's own normals
    averaged, _ = without_near_mirror(*inputs, average_fraction=0.1)
    assert not np.isfinite(averaged[0].distance[highlight]).any()
    assert np.isfinite(averaged[0].distance[far]).all()


def test_examples_in_the_docstrings_run() -> None:
    import doctest

    import reconstruct.initial_mesh.dense.mirror

    result = doctest.testmod(reconstruct.initial_mesh.dense.mirror)
    assert result.attempted > 0 and result.failed == 0
