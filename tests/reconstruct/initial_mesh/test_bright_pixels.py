"""Depth-map pixels brighter than their surface point looks from the other views, dropped."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from reconstruct.initial_mesh.dense.bright_pixels import diffuse_levels, without_bright
from reconstruct.initial_mesh.dense.mirror import averaged_vertex_normals
from reconstruct.initial_mesh.dense.patchmatch import ViewDepth
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.forward import half_angles, shading
from reconstruct.model.raycast import RayCaster

RADIUS = 0.1
SIZE = 160
OFFSET = np.array([0.08, 0.0, 0.0])  # the lamp 8 cm beside the lens
RATIO = 1.2  # what bench/README.md measured on glossy scenes


def _albedo(x: np.ndarray) -> np.ndarray:
    """A painted pattern: stripes of albedo 0.2 and 0.7 round the sphere."""
    return np.where(np.sin(40 * x[:, 1]) > 0, 0.7, 0.2)


def _inside_a_stripe(x: np.ndarray) -> np.ndarray:
    """Whether points lie 6 mm or more from a stripe's edge."""
    return np.abs(np.sin(40 * x[:, 1])) > np.sin(40 * 0.006)


def _render(sphere: trimesh.Trimesh, caster: RayCaster, pose: Pose, intr: Intrinsics,
            gloss: float) -> tuple[np.ndarray, ViewDepth, np.ndarray, np.ndarray]:
    """A view's two-channel image of the painted sphere under its own lamp, with a highlight
    of ``gloss`` times the diffuse peak at the mirror direction; its depth map; each pixel's
    half-angle (degrees, NaN off the sphere); and whether it lies inside a stripe."""
    rr, cc = np.mgrid[0:SIZE, 0:SIZE]
    rays = intr.pixel_rays(np.stack([cc.ravel() + 0.5, rr.ravel() + 0.5], 1)) @ pose.R
    _, distance, _ = caster.first_hit(np.broadcast_to(pose.center, rays.shape), rays)
    hit = np.isfinite(distance)
    x = pose.center + rays[hit] * distance[hit, None]
    light = pose.light_position(OFFSET)
    s = shading(x, x / RADIUS, light)
    angle = half_angles(x, x / RADIUS, np.broadcast_to(light, x.shape),
                        np.broadcast_to(pose.center, x.shape))
    peak = 0.7 * float(s.max())
    value = np.zeros(SIZE * SIZE)
    value[hit] = _albedo(x) * s + gloss * peak * np.exp(-((angle / np.radians(8)) ** 2))
    image = np.stack([value, 0.5 * value], axis=-1).reshape(SIZE, SIZE, 2)
    depth = np.where(hit, distance, np.nan).reshape(SIZE, SIZE)
    degrees = np.full(SIZE * SIZE, np.nan)
    degrees[hit] = np.degrees(angle)
    inside = np.zeros(SIZE * SIZE, bool)
    inside[hit] = _inside_a_stripe(x)
    vd = ViewDepth(depth, np.zeros((SIZE, SIZE, 3)), np.zeros((SIZE, SIZE)), intr)
    return image, vd, degrees.reshape(SIZE, SIZE), inside.reshape(SIZE, SIZE)


class Ring:
    """Views 15° apart round a painted sphere, each with its own highlight of ``gloss``."""

    def __init__(self, degrees: range, gloss: float) -> None:
        self.sphere = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS)
        caster = RayCaster(np.asarray(self.sphere.vertices), np.asarray(self.sphere.faces))
        intr = Intrinsics.pinhole(SIZE, SIZE, 370.0)
        self.images, self.maps, self.poses, self.angles, self.inside = {}, {}, {}, {}, {}
        for view, deg in enumerate(degrees):
            a = np.radians(deg)
            pose = Pose.look_at(0.5 * np.array([np.sin(a), 0.0, np.cos(a)]), np.zeros(3))
            self.poses[view] = pose
            (self.images[view], self.maps[view], self.angles[view],
             self.inside[view]) = _render(self.sphere, caster, pose, intr, gloss)
        self.masks = {v: np.isfinite(vd.distance) for v, vd in self.maps.items()}

    def without_bright(self, reach_px: int) -> tuple[dict[int, ViewDepth], int]:
        return without_bright(self.maps, self.images, self.masks, self.poses, OFFSET,
                              self.sphere, RATIO, reach_px)


@pytest.fixture(scope="module")
def ring() -> Ring:
    return Ring(range(-45, 46, 15), 1.0)


def test_a_points_level_is_its_albedo_whatever_the_highlights(ring: Ring) -> None:
    normals = averaged_vertex_normals(ring.sphere, 0.0)
    levels = diffuse_levels(ring.sphere, normals, ring.images, ring.masks, ring.maps,
                            ring.poses, OFFSET)
    seen = np.isfinite(levels)
    assert seen.mean() > 0.3
    # the sum of the two channels is 1.5 × albedo × shading
    expected = 1.5 * _albedo(np.asarray(ring.sphere.vertices))[seen]
    assert np.median(np.abs(levels[seen] / expected - 1)) < 0.02


def test_the_highlight_is_dropped_and_the_paint_kept(ring: Ring) -> None:
    out, dropped = ring.without_bright(0)
    for view, vd in ring.maps.items():
        on = np.isfinite(vd.distance)
        kept = np.isfinite(out[view].distance)
        assert np.array_equal(out[view].distance[kept], vd.distance[kept])
        angle = ring.angles[view]
        # the pixels at the highlight's peak are dropped, those beyond its reach are kept;
        # beside an edge of the paint a pixel is judged against the lighter paint's level
        assert not kept[on & ring.inside[view] & (angle < 4.0)].any()
        assert kept[on & (angle > 20.0)].all()
    assert dropped == sum(int(np.isfinite(vd.distance).sum() - np.isfinite(out[v].distance).sum())
                          for v, vd in ring.maps.items()) > 100


def test_a_dropped_pixel_takes_the_pixels_its_matching_window_reaches(ring: Ring) -> None:
    bare, _ = ring.without_bright(0)
    wide, _ = ring.without_bright(2)
    for view in ring.maps:
        bare_kept, wide_kept = np.isfinite(bare[view].distance), np.isfinite(wide[view].distance)
        assert not (wide_kept & ~bare_kept).any()
        assert (bare_kept & ~wide_kept).sum() > 0


def test_a_matte_surface_loses_nothing() -> None:
    matte = Ring(range(-30, 31, 15), 0.0)
    out, dropped = matte.without_bright(2)
    assert dropped == 0
    assert all(np.array_equal(out[v].distance, vd.distance, equal_nan=True)
               for v, vd in matte.maps.items())
