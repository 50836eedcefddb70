"""The renderer's real optics, as the simulator uses them: a bulb with a size (the point
light's irradiance wherever all of it is seen, soft shadow edges, light past the horizon) and a
neutral GGX gloss lobe (a highlight at the mirror direction, nothing elsewhere)."""

from __future__ import annotations

import numpy as np

from reconstruct.model import render
from reconstruct.model.bulb import cone_samples, rim_points
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.raycast import RayCaster
from tests.plates import join, rectangle

PLATE = rectangle([-0.1, -0.1, 0.0], [0.2, 0.0, 0.0], [0.0, 0.2, 0.0], 21)  # facing +z
TOP = Pose.look_at(np.array([0.0, 0.0, 0.3]), np.zeros(3), up=(0.0, 1.0, 0.0))
INTR = Intrinsics.pinhole(120, 120, 160.0)


def hits_of(mesh: tuple[np.ndarray, np.ndarray]) -> tuple[RayCaster, render.ViewHits]:
    caster = RayCaster(*mesh)
    return caster, render.trace_view(caster, INTR, TOP, supersample=1)


def test_rim_points_lie_across_the_line_of_sight_and_cone_samples_on_the_bulb() -> None:
    points = np.array([[0.0, 0.0, 0.0], [0.3, -0.2, 0.1]])
    centre = np.array([0.05, 0.02, 0.5])
    sight = centre - points
    rim = rim_points(points, centre, 0.03, 6) - centre
    np.testing.assert_allclose(np.einsum("snk,nk->sn", rim, sight), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(rim, axis=2), 0.03)
    targets, scale = cone_samples(points, centre, 0.03, 16)
    np.testing.assert_allclose(np.linalg.norm(targets - centre, axis=2), 0.03)  # on the sphere
    # on its near side, and every direction inside the cone the sphere subtends
    assert np.all(np.einsum("snk,nk->sn", targets - centre, sight) < 0)
    rays = targets - points
    cos = np.einsum("snk,nk->sn", rays, sight) / (
        np.linalg.norm(rays, axis=2) * np.linalg.norm(sight, axis=1)
    )
    assert np.all(cos >= np.sqrt(1 - (0.03 / np.linalg.norm(sight, axis=1)) ** 2) - 1e-12)
    assert scale.shape == (2,)


def test_a_fully_seen_bulb_lights_as_the_point_at_its_centre() -> None:
    caster, hits = hits_of(PLATE)
    light = np.array([0.1, 0.05, 0.4])
    point = render.light_weight(caster, hits, light)
    bulb = render.light_weight(caster, hits, light, radius=0.03)
    assert np.all(point > 0)
    np.testing.assert_allclose(bulb, point, rtol=1e-9)  # a uniform sphere's field outside it


def test_a_bulb_casts_a_penumbra_and_lights_past_the_horizon() -> None:
    wall = rectangle([0.0, -0.1, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.05], 11)
    caster, hits = hits_of(join(PLATE, wall)[:2])
    light = np.array([0.05, 0.0, 0.2])  # the point's shadow ends at x = -1/60 m
    point = render.light_weight(caster, hits, light)
    bulb = render.light_weight(caster, hits, light, radius=0.03)
    x = hits.points[:, 0]
    plate = (np.abs(hits.points[:, 2]) < 1e-9) & (np.abs(hits.points[:, 1]) < 0.05)
    deep = plate & (x > -0.004) & (x < -0.001)
    edge = plate & (x > -0.022) & (x < -0.019)  # lit by the centre, not by all of the bulb
    open_ = plate & (x < -0.035)
    assert np.all(point[deep] == 0) and np.all(point[edge] > 0)
    assert np.all(bulb[edge] < 0.9 * point[edge]) and np.all(bulb[edge] > 0)
    np.testing.assert_allclose(bulb[open_], point[open_], rtol=1e-9)
    # the bulb's centre just below the plate's plane: the point lights nothing, the bulb's
    # upper part still does, most near it
    low = np.array([0.15, 0.0, -0.005])
    caster, hits = hits_of(PLATE)
    assert np.all(render.light_weight(caster, hits, low) == 0)
    grazing = render.light_weight(caster, hits, low, radius=0.03)
    near, far = hits.points[:, 0] > 0.06, hits.points[:, 0] < -0.06
    assert grazing[near].mean() > 2 * grazing[far].mean() > 0


def test_the_gloss_lobe_peaks_at_the_mirror_direction() -> None:
    caster, hits = hits_of(PLATE)
    light = np.array([0.0, 0.0, 0.3])  # at the camera: the highlight at the plate's centre
    lit = render.light_weight(caster, hits, light)
    gloss = render.specular_weight(hits, light, TOP.center, lit, 0.04, 0.2)
    centre = np.argmin(np.linalg.norm(hits.points[:, :2], axis=1))
    assert gloss.argmax() == centre
    # at the mirror direction: π D F G / (4 cos²) · s with D = 1 / (π α²), F = 0.04, G ≈ 1
    expected = 0.04 / (4 * 0.2**2) * lit[centre]
    np.testing.assert_allclose(gloss[centre], expected, rtol=0.01)
    corners = np.linalg.norm(hits.points[:, :2], axis=1) > 0.09
    assert np.all(gloss[corners] < 0.15 * gloss[centre])  # α 0.2: a broad lobe
    assert np.all(gloss >= 0)
