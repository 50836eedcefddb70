"""Depth-map pixels brighter than their surface point looks from the other views, dropped."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from reconstruct.initial_mesh.dense.bright_pixels import (
    fit_albedo_normals,
    view_readings,
    without_bright,
)
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
    """Views 15° apart round a painted sphere at two heights (a stepped trajectory: the
    lamp directions must not all lie in one plane for a fit), each with its own highlight
    of ``gloss``."""

    def __init__(self, degrees: range, gloss: float) -> None:
        self.sphere = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS)
        caster = RayCaster(np.asarray(self.sphere.vertices), np.asarray(self.sphere.faces))
        intr = Intrinsics.pinhole(SIZE, SIZE, 370.0)
        self.images, self.maps, self.poses, self.angles, self.inside = {}, {}, {}, {}, {}
        steps = [(deg, height) for height in (-0.15, 0.15) for deg in degrees]
        # views with others on both sides: from the sweep's ends a highlight looks like the
        # normal tilted towards the last view
        self.inner = [view for view, (deg, _) in enumerate(steps)
                      if min(degrees) < deg < max(degrees)]
        for view, (deg, height) in enumerate(steps):
            a = np.radians(deg)
            eye = np.array([0.5 * np.sin(a), height, 0.5 * np.cos(a)])
            pose = Pose.look_at(eye, np.zeros(3))
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


def test_the_fit_is_albedo_times_normal_whatever_the_highlights(ring: Ring) -> None:
    caster = RayCaster(np.asarray(ring.sphere.vertices), np.asarray(ring.sphere.faces))
    # a start 30° off the truth, as a deformed first surface's normals are
    true_normals = np.asarray(ring.sphere.vertex_normals)
    start = true_normals + 0.58 * np.cross(true_normals, [0.0, 1.0, 0.0])
    start /= np.linalg.norm(start, axis=1, keepdims=True)
    readings = view_readings(ring.sphere, start, ring.images, ring.masks, ring.maps,
                             ring.poses, OFFSET, caster)
    fit = fit_albedo_normals(*readings, start)
    fitted = np.isfinite(fit[:, 0]) & _inside_a_stripe(np.asarray(ring.sphere.vertices))
    assert fitted.mean() > 0.2
    # the sum of the two channels is 1.5 × albedo × shading
    expected = 1.5 * _albedo(np.asarray(ring.sphere.vertices))[:, None] * true_normals
    error = np.linalg.norm(fit - expected, axis=1) / np.linalg.norm(expected, axis=1)
    assert np.median(error[fitted]) < 0.01
    # the highlights are left out of the fit, so it holds at their peaks too
    highlighted = np.isin(np.arange(len(fit)), _peaks(ring)) & fitted
    assert highlighted.sum() > 10
    assert np.median(error[highlighted]) < 0.03


def _peaks(ring: Ring) -> np.ndarray:
    """The vertices within 4° of some view's mirror direction."""
    x = np.asarray(ring.sphere.vertices)
    near = np.zeros(len(x), bool)
    for pose in ring.poses.values():
        light = np.broadcast_to(pose.light_position(OFFSET), x.shape)
        camera = np.broadcast_to(pose.center, x.shape)
        near |= half_angles(x, x / RADIUS, light, camera) < np.radians(4)
    return np.flatnonzero(near)


def test_the_highlight_is_dropped_and_the_paint_kept(ring: Ring) -> None:
    out, dropped = ring.without_bright(0)
    for view, vd in ring.maps.items():
        on = np.isfinite(vd.distance)
        kept = np.isfinite(out[view].distance)
        assert np.array_equal(out[view].distance[kept], vd.distance[kept])
        angle = ring.angles[view]
        # the pixels at the highlight's peak are dropped, those beyond its reach are kept
        if view in ring.inner:
            assert not kept[on & ring.inside[view] & (angle < 4.0)].any()
        assert kept[on & ring.inside[view] & (angle > 20.0)].all()
        # beside an edge of the paint a pixel is judged against the lighter paint's fit, but
        # a corner whose readings mix the two paints is fitted low, or not at all
        beside_an_edge = on & ~ring.inside[view] & (angle > 20.0)
        assert (beside_an_edge & ~kept).sum() <= 0.02 * beside_an_edge.sum()
    assert dropped == sum(int(np.isfinite(vd.distance).sum() - np.isfinite(out[v].distance).sum())
                          for v, vd in ring.maps.items()) > 100


def test_a_dropped_pixel_takes_the_pixels_its_matching_window_reaches(ring: Ring) -> None:
    bare, _ = ring.without_bright(0)
    wide, _ = ring.without_bright(2)
    for view in ring.maps:
        bare_kept, wide_kept = np.isfinite(bare[view].distance), np.isfinite(wide[view].distance)
        assert not (wide_kept & ~bare_kept).any()
        assert (bare_kept & ~wide_kept).sum() > 0


def test_a_matte_surface_keeps_its_paint_and_most_of_its_edges() -> None:
    matte = Ring(range(-30, 31, 15), 0.0)
    out, dropped = matte.without_bright(0)
    beside_an_edge = 0
    for view, vd in matte.maps.items():
        on = np.isfinite(vd.distance)
        kept = np.isfinite(out[view].distance)
        assert kept[on & matte.inside[view]].all()
        beside_an_edge += int((on & ~matte.inside[view]).sum())
    assert dropped <= 0.01 * beside_an_edge


def test_the_docstring_examples_hold() -> None:
    import doctest

    from reconstruct.initial_mesh.dense import bright_pixels

    assert doctest.testmod(bright_pixels).failed == 0
