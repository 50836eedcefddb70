"""The compiled preconditioner, render and CG kernels against their plain NumPy definitions."""

from __future__ import annotations

import numpy as np
import pytest

from reconstruct.optimise.kernels.cg import cg_direction, cg_step, project_to_stage
from reconstruct.optimise.kernels.preconditioner import (
    back_substitute_light,
    coupling_transpose_product,
    damped_block_inverses,
    expand_positions,
    solve_vertex_blocks,
)
from reconstruct.optimise.kernels.rendering import rendered_error


def _spd_blocks(rng: np.random.Generator, n: int, size: int) -> np.ndarray:
    a = rng.normal(size=(n, size + 2, size))
    return a.transpose(0, 2, 1) @ a


@pytest.mark.parametrize("along_normal", [False, True])
def test_damped_block_inverses_invert_the_projected_masked_blocks(along_normal: bool) -> None:
    rng = np.random.default_rng(3)
    n, nb = 6, 4
    blocks = _spd_blocks(rng, n, 3 + nb)
    damping = rng.uniform(0.1, 1.0, size=(n, 3 + nb))
    if along_normal:
        normal = rng.normal(size=(n, 3))
        shapes = (normal / np.linalg.norm(normal, axis=1, keepdims=True))[:, :, None]
    else:
        shapes = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    shapes[0] = 0.0  # vertex 0: positions fixed
    alpha_mask = np.ones((n, nb))
    alpha_mask[1] = 0.0  # vertex 1: reflectance fixed
    m = shapes.shape[2]
    got = damped_block_inverses(blocks, damping, shapes, alpha_mask)
    for i in range(n):
        basis = np.zeros((3 + nb, m + nb))
        basis[:3, :m] = shapes[i]
        basis[3:, m:] = np.diag(alpha_mask[i])
        projected = basis.T @ (blocks[i] + np.diag(damping[i])) @ basis
        dead = ~np.abs(basis).any(axis=0)
        projected[dead, dead] = 1.0
        assert np.allclose(got[i], np.linalg.inv(projected), rtol=1e-9, atol=1e-12)


def test_vertex_block_solve_and_expansion_match_the_dense_products() -> None:
    rng = np.random.default_rng(5)
    n, m, nb = 5, 1, 3
    inverse = rng.normal(size=(n, m + nb, m + nb))
    shapes = rng.normal(size=(n, 3, m))
    vx, va = rng.normal(size=(n, 3)), rng.normal(size=(n, nb))
    z = solve_vertex_blocks(inverse, shapes, vx, va)
    u = np.concatenate([np.einsum("nam,na->nm", shapes, vx), va], axis=1)
    assert np.allclose(z, np.einsum("nij,nj->ni", inverse, u))
    assert np.allclose(expand_positions(shapes, z), np.einsum("nam,nm->na", shapes, z[:, :m]))


@pytest.mark.parametrize("m", [1, 3])
def test_light_elimination_matches_the_dense_products(m: int) -> None:
    rng = np.random.default_rng(9)
    n, nb = 6, 4
    k = m + nb
    coupling, dinv_c = rng.normal(size=(n, k, 3)), rng.normal(size=(n, k, 3))
    z, light = rng.normal(size=(n, k)), rng.normal(size=3)
    shapes = rng.normal(size=(n, 3, m))
    alpha_mask = (rng.random((n, nb)) > 0.3).astype(float)
    assert np.allclose(
        coupling_transpose_product(coupling, z), coupling.reshape(-1, 3).T @ z.ravel()
    )
    theta = np.full(3 * n + nb * n, np.nan)  # the kernel writes into views of it
    out_x, out_a = theta[: 3 * n].reshape(n, 3), theta[3 * n :].reshape(n, nb)
    back_substitute_light(z, dinv_c, light, shapes, alpha_mask, out_x, out_a)
    corrected = z - dinv_c @ light
    assert np.allclose(theta[: 3 * n], np.einsum("nam,nm->na", shapes, corrected[:, :m]).ravel())
    assert np.allclose(theta[3 * n :], (corrected[:, m:] * alpha_mask).ravel())


def test_rendered_error_is_shading_times_colour_minus_observed() -> None:
    rng = np.random.default_rng(6)
    colours = rng.uniform(size=(2, 4, 3))
    pair_shading = rng.uniform(size=3)
    obs_pair = np.array([0, 0, 1, 2, 2])
    vertex = np.array([0, 0, 1, 3, 3])
    illumination = np.array([0, 1, 0, 0, 1])
    observed = rng.uniform(size=(5, 3))
    error = rendered_error(colours, pair_shading, obs_pair, vertex, illumination, observed)
    s, colour = pair_shading[obs_pair], colours[illumination, vertex]
    assert np.allclose(error, s[:, None] * colour - observed, rtol=1e-14, atol=1e-15)


def test_cg_updates_match_their_vector_definitions() -> None:
    rng = np.random.default_rng(11)
    x, r, d, q, z = rng.normal(size=(5, 40))
    x0, r0, d0 = x.copy(), r.copy(), d.copy()
    squared = cg_step(x, r, d, q, 0.7)
    assert np.allclose(x, x0 + 0.7 * d0) and np.allclose(r, r0 - 0.7 * q)
    assert np.isclose(squared, r @ r)
    cg_direction(d, z, 0.3)
    assert np.allclose(d, z + 0.3 * d0)


@pytest.mark.parametrize("along_normal", [False, True])
@pytest.mark.parametrize("damped", [False, True])
def test_projection_to_the_stage_masks_damps_and_moves_along_directions(
    along_normal: bool, damped: bool
) -> None:
    rng = np.random.default_rng(12)
    n, extra = 4, 5  # 4 vertices (12 position entries), then other parameters
    v, step = rng.normal(size=(2, 3 * n + extra))
    mask = rng.random(3 * n + extra) > 0.3
    damping = rng.uniform(size=v.size) if damped else np.empty(0)
    directions = np.empty((0, 3))  # free motion
    if along_normal:
        directions = rng.normal(size=(n, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    got = v.copy()
    project_to_stage(got, damping, step, mask, directions)
    want = (v + (damping * step if damped else 0.0)) * mask
    if along_normal:
        x = want[: 3 * n].reshape(n, 3)
        want[: 3 * n] = (directions * np.einsum("ij,ij->i", x, directions)[:, None]).ravel()
    assert np.allclose(got, want, rtol=1e-14, atol=1e-15)
