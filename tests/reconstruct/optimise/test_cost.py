"""The joint cost: residuals from the forward model, every Jacobian block against finite
differences, and the factored Gauss–Newton pieces against the explicit sparse Jacobian."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from reconstruct.model.forward import render_values, response_matrix, shading
from reconstruct.optimise.cost import JointCost, seen_projection
from reconstruct.optimise.mesh import vertex_normals
from reconstruct.optimise.solver import ArrowheadPreconditioner
from reconstruct.optimise.synthetic import SyntheticScene
from tests.reconstruct.conftest import cost_at, problem_at


def test_rendering_residual_is_zero_at_the_truth(scene: SyntheticScene) -> None:
    problem, _ = problem_at(scene, images=False)
    cost = JointCost(problem)
    theta = problem.pack(scene.vertices, scene.alpha, scene.light_offset)
    terms = cost.terms(theta)
    assert terms["rendering"] < 1e-20
    assert terms["total"] == pytest.approx(float(np.sum(cost.residuals(theta) ** 2)))


def test_rendering_uses_the_forward_model(scene: SyntheticScene) -> None:
    problem, theta = problem_at(scene, images=False)
    cost = JointCost(problem)
    X, A, light = problem.unpack(theta)
    normals, _ = cost.geometry(X, False).normals, None
    st = cost.render(X, A, light, normals, derivatives=False)
    o = problem.obs
    P = problem.light_positions(light)
    i = o.vertex[:50]
    s = shading(X[i], normals[i], P[o.view[:50]])
    refl = scene.basis.reconstruct(A[i])
    rendered = st.pair_s[cost.obs_pair[:50], None] * st.colours[o.illumination[:50], i]
    for k in range(2):
        sel = o.illumination[:50] == k
        y = render_values(refl[sel], s[sel], problem.rig.responses[k])
        assert np.allclose(rendered[sel], y)
    assert np.allclose(problem.rig.responses[0], response_matrix_like(problem.rig.responses[0]))


def response_matrix_like(resp: np.ndarray) -> np.ndarray:
    """Rebuild a response from its own rows (C^T diag(L) with L = 1): a shape check."""
    return response_matrix(resp.T, np.ones(resp.shape[1]))


@pytest.mark.parametrize("mode", ["offset", "free"])
@pytest.mark.parametrize("images", [False, True])
def test_jacobian_blocks_match_finite_differences(
    scene: SyntheticScene, image_scene: SyntheticScene, mode: str, images: bool
) -> None:
    sc = image_scene if images else scene
    cost, theta = cost_at(sc, images, mode)
    J = cost.jacobian(theta)
    assert J.shape == (cost.residuals(theta).size, theta.size)
    rng = np.random.default_rng(4)
    sx, sa, sl = cost.p.slices()
    for block, scale in ((sx, 1e-4), (sa, 1.0), (sl, 1e-2)):
        d = np.zeros_like(theta)
        d[block] = scale * rng.normal(size=block.stop - block.start)
        h = 1e-6
        fd = (cost.residuals(theta + h * d) - cost.residuals(theta - h * d)) / (2 * h)
        an = J @ d
        assert np.linalg.norm(fd - an) <= 1e-6 * np.linalg.norm(an)


def _weighted_system(cost: JointCost, theta: np.ndarray) -> tuple[sp.csr_array, np.ndarray]:
    """The explicit Jacobian and residual with the robust loss's IRLS weights on the rendering
    rows: the system the factored Gauss–Newton pieces must reproduce."""
    J = cost.jacobian(theta)
    r = cost.residuals(theta)
    X, A, light = cost.p.unpack(theta)
    st = cost.render(X, A, light, cost.geometry(X, False).normals, derivatives=False)
    _, rw = cost._robust(st.error)
    d = np.ones(len(r))
    d[: 3 * cost.p.obs.count] = np.repeat(rw, 3)
    return (sp.diags_array(d) @ J).tocsr(), d * r


@pytest.mark.parametrize("mode", ["offset", "free"])
@pytest.mark.parametrize("images", [False, True])
@pytest.mark.parametrize("robust", ["none", "huber"])
def test_factored_normal_equations_match_explicit_jacobian(
    scene: SyntheticScene, image_scene: SyntheticScene, mode: str, images: bool, robust: str
) -> None:
    sc = image_scene if images else scene
    problem, theta = problem_at(sc, images, mode)
    cost = JointCost(problem, robust=robust, robust_scale=0.002)  # type: ignore[arg-type]
    J, r = _weighted_system(cost, theta)
    if robust != "none":
        assert (
            np.ptp(
                r[: 3 * problem.obs.count : 3] / cost.residuals(theta)[: 3 * problem.obs.count : 3]
            )
            > 0.1
        )
    lin = cost.linearise(theta)
    g = J.T @ r
    assert np.allclose(lin.gradient(), g, rtol=1e-10, atol=1e-10 * np.abs(g).max())
    v = np.random.default_rng(5).normal(size=theta.size)
    hv = J.T @ (J @ v)
    assert np.allclose(lin.matvec(v), hv, rtol=1e-10, atol=1e-10 * np.abs(hv).max())
    H = (J.T @ J).tocsr()
    hmax = np.abs(H.data).max()
    vert, light = lin.diagonal_blocks()
    n, nb = cost.p.n_vertices, cost.p.n_basis
    nx = 3 * n
    rows = np.concatenate(
        [np.r_[3 * i : 3 * i + 3, nx + nb * i : nx + nb * (i + 1)] for i in range(n)]
    )
    for i in range(0, n, 7):
        idx = rows[(3 + nb) * i : (3 + nb) * (i + 1)]
        assert np.allclose(vert[i], H[idx][:, idx].toarray(), rtol=1e-10, atol=1e-10 * hmax)
    for j in range(len(light)):
        idx = sl_index(cost, j)
        assert np.allclose(light[j], H[idx][:, idx].toarray(), rtol=1e-10, atol=1e-10 * hmax)
    # The vertex–light coupling the preconditioner borders with is H's block for α.
    coupling = lin.light_coupling()
    C = (
        coupling.reshape(n * (3 + nb), 3)
        if isinstance(coupling, np.ndarray)
        else coupling.toarray()
    )
    ref = H[rows][:, np.arange(problem.slices()[2].start, problem.size)].toarray()
    alpha_rows = np.tile(np.arange(3 + nb) >= 3, n)
    assert np.allclose(C[alpha_rows], ref[alpha_rows], rtol=1e-10, atol=1e-10 * hmax)


def sl_index(cost: JointCost, j: int) -> np.ndarray:
    sl = cost.p.slices()[2]
    return np.arange(sl.start + 3 * j, sl.start + 3 * j + 3)


@pytest.mark.parametrize("normal", [False, True])
@pytest.mark.parametrize("mode", ["offset", "free"])
def test_preconditioner_inverts_the_bordered_block_diagonal(
    scene: SyntheticScene, mode: str, normal: bool
) -> None:
    """With directions it inverts the blocks of the projected system (x = h d per vertex)."""
    cost, theta = cost_at(scene, False, mode)
    lin = cost.linearise(theta)
    blocks = lin.diagonal_blocks()
    p = cost.p
    mask = p.mask(True, True, True)
    scale = np.ones(p.size)
    lam = 0.1
    directions = vertex_normals(scene.vertices, scene.faces)[0] if normal else None
    pre = ArrowheadPreconditioner(lin, blocks, lam, scale, mask, directions)
    # The approximated matrix in θ's layout: vertex blocks, light blocks, coupling.
    n, nb = p.n_vertices, p.n_basis
    k = 3 + nb
    order = np.concatenate(
        [np.r_[3 * i : 3 * i + 3, 3 * n + nb * i : 3 * n + nb * (i + 1)] for i in range(n)]
        + [np.arange(p.slices()[2].start, p.size)]
    )  # vertex-interleaved position of each θ entry
    vert, light = blocks
    coupling = lin.light_coupling()
    C = coupling.reshape(n * k, 3) if isinstance(coupling, np.ndarray) else coupling.toarray()
    light_dense = sp.block_diag(list(light)).toarray() + lam * np.eye(p.n_light)
    M = sp.block_array(
        [
            [sp.block_diag(list(vert + lam * np.eye(k))), sp.csr_array(C)],
            [sp.csr_array(C.T), sp.csr_array(light_dense)],
        ]
    ).tocsr()
    M = M[np.argsort(order)][:, np.argsort(order)]  # back to θ's layout
    # Allowed motion: per vertex its direction (or the axes), α and light.
    U = sp.eye_array(p.size, format="csr")
    if directions is not None:
        rows = 3 * np.arange(n)[:, None] + np.arange(3)
        x = sp.csr_array((directions.ravel(), (rows.ravel(), np.repeat(np.arange(n), 3))))
        U = sp.block_diag([x, sp.eye_array(p.size - 3 * n)]).tocsr()
    v = np.random.default_rng(6).normal(size=p.size)
    expected = U @ spsolve((U.T @ M @ U).tocsc(), U.T @ v)
    assert np.allclose(pre(v), expected, rtol=1e-8, atol=1e-8 * np.abs(expected).max())


@pytest.mark.parametrize("images", [False, True])
def test_fixed_positions_keep_reflectance_and_light_parts_exact(
    scene: SyntheticScene, image_scene: SyntheticScene, images: bool
) -> None:
    """A light/reflectance-only stage skips the position derivatives; what it solves for
    stays exact."""
    sc = image_scene if images else scene
    cost, theta = cost_at(sc, images)
    full = cost.linearise(theta)
    part = cost.linearise(theta, positions=False)
    assert part.terms == full.terms
    free = ~cost.p.mask(True, False, False)
    assert np.allclose(part.gradient()[free], full.gradient()[free], rtol=1e-12, atol=0)
    v = np.random.default_rng(7).normal(size=theta.size) * free
    assert np.allclose(part.matvec(v)[free], full.matvec(v)[free], rtol=1e-12, atol=1e-12)
    (vp, lp), (vf, lf) = part.diagonal_blocks(), full.diagonal_blocks()
    assert np.allclose(vp[:, 3:, 3:], vf[:, 3:, 3:], rtol=1e-12) and np.allclose(lp, lf)


def test_neighbours_are_compared_on_what_the_responses_see(scene: SyntheticScene) -> None:
    """Spectra that render alike cost nothing in the photometric term: what no observation
    holds is the spectral regulariser's, vertex by vertex, not passed along the mesh."""
    problem, theta = problem_at(scene, images=False)
    cost = JointCost(problem)
    X, A, light = problem.unpack(theta)
    rows = cost.Q.reshape(-1, cost.Q.shape[-1])
    unseen = np.linalg.svd(rows)[2][-1]  # a weight direction every response is blind to
    assert np.abs(rows @ unseen).max() < 1e-9 * np.abs(rows).max()
    shift = np.random.default_rng(0).normal(0.0, 0.05, len(A))[:, None] * unseen
    before = cost.terms(theta)
    after = cost.terms(problem.pack(X, A + shift, light))
    assert before["photometric"] > 0
    assert after["photometric"] == pytest.approx(before["photometric"], rel=1e-9)
    assert after["spectral"] != pytest.approx(before["spectral"], rel=1e-3)


def test_the_seen_part_is_the_smallest_spectrum_that_renders_alike(scene: SyntheticScene) -> None:
    problem, _ = problem_at(scene, images=False)
    B, Q = scene.basis.B, JointCost(problem).Q
    rows = Q.reshape(-1, Q.shape[-1])
    P = seen_projection(B, Q)
    a = np.random.default_rng(1).normal(size=B.shape[1])
    np.testing.assert_allclose(P @ P, P, atol=1e-10)
    np.testing.assert_allclose(rows @ (P @ a), rows @ a, rtol=1e-9)
    unseen = np.linalg.svd(rows)[2][-1]
    for t in (-0.3, 0.1, 0.5):
        assert np.linalg.norm(B @ (P @ a)) < np.linalg.norm(B @ (P @ a + t * unseen))
