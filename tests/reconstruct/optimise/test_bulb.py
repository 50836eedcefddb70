"""A bulb with a size: the observations that see only part of it (across their horizon, or in a
penumbra) are left out of the solve, the rest keep the point light's exact irradiance."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from reconstruct.model.raycast import RayCaster
from reconstruct.optimise.mesh import vertex_normals
from reconstruct.optimise.problem_setup import build_problem, light_positions, rim_hidden
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.synthetic import SyntheticScene
from tests.plates import rectangle


def test_rim_rays_find_the_penumbra_the_centre_ray_misses() -> None:
    """A 5 cm wall at x = 0 on a plate, the bulb (3 cm radius) at (5, 0, 20) cm: the point
    light's shadow ends at x = −1.67 cm, the bulb's penumbra reaches x = −2.67 cm."""
    wall_v, wall_f = rectangle([0.0, -0.1, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.05], 11)
    caster = RayCaster(wall_v, wall_f)
    x = np.array([-0.06, -0.04, -0.024, -0.02, -0.01])
    points = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    centre = np.tile([0.05, 0.0, 0.2], (len(x), 1))
    centre_hidden = caster.occluded(points, centre, 1e-6, normals)
    np.testing.assert_array_equal(centre_hidden, [False, False, False, False, True])
    hidden = rim_hidden(caster, points, centre, normals, 0.03, 1e-6)
    np.testing.assert_array_equal(hidden, [False, False, True, True, True])
    # a bulb the size of a point changes nothing
    np.testing.assert_array_equal(rim_hidden(caster, points, centre, normals, 1e-9, 1e-6),
                                  centre_hidden)  # fmt: skip


def test_a_sized_bulb_leaves_out_what_sees_part_of_it(scene: SyntheticScene) -> None:
    cfg = OptimiseSettings()
    light = scene.light_offset[None]
    point = build_problem(scene.input(), scene.vertices, light, cfg)
    tiny = build_problem(replace(scene.input(), light_radius=1e-9), scene.vertices, light, cfg)
    bulb = build_problem(replace(scene.input(), light_radius=0.03), scene.vertices, light, cfg)
    assert tiny.obs.count == point.obs.count
    assert point.obs.count * 0.5 < bulb.obs.count < point.obs.count
    # what is kept is a subset, and every kept observation sees the whole bulb above its horizon
    kept = set(zip(bulb.obs.vertex.tolist(), bulb.obs.frame.tolist(), strict=True))
    assert kept <= set(zip(point.obs.vertex.tolist(), point.obs.frame.tolist(), strict=True))
    normals, _ = vertex_normals(scene.vertices, scene.faces)
    P = light_positions(scene.rig, cfg.light_mode, light)[scene.frames.view[bulb.obs.frame]]
    to_light = P - scene.vertices[bulb.obs.vertex]
    d = np.linalg.norm(to_light, axis=1)
    cos = np.einsum("ij,ij->i", normals[bulb.obs.vertex], to_light) / d
    assert np.all(cos > 0.03 / d)
