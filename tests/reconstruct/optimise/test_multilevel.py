"""The two-level preconditioners (patches with LU, the whole position block with an AMG
V-cycle): the coarse operator against the explicit Jacobian, symmetric positive definiteness,
fewer CG iterations than the block preconditioner, and a solve with each reaching the same
cost."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from core.errors import RigError
from reconstruct.optimise.cost import JointCost
from reconstruct.optimise.mesh import vertex_normals
from reconstruct.optimise.multilevel import CoarseOperator, patch_bumps
from reconstruct.optimise.problem import Problem
from reconstruct.optimise.solver import (
    ArrowheadPreconditioner,
    SolverSettings,
    _diagonal,
    _pcg,
    levenberg_marquardt,
)
from reconstruct.optimise.steps import OptimiseSettings, build_problem
from reconstruct.optimise.synthetic import SyntheticScene, make_scene, perturb
from tests.reconstruct.conftest import cost_at


def _projection(p: Problem, mask: np.ndarray, directions: np.ndarray | None) -> sp.csr_array:
    """The solver's step projection as a matrix: the mask, then d dᵀ per vertex."""
    P = sp.diags_array(mask.astype(float)).tocsr()
    if directions is None:
        return P
    n = p.n_vertices
    rows = 3 * np.arange(n)[:, None, None] + np.arange(3)[None, :, None]
    cols = 3 * np.arange(n)[:, None, None] + np.arange(3)[None, None, :]
    rows, cols = np.broadcast_arrays(rows, cols)
    dd = directions[:, :, None] * directions[:, None, :]
    xx = sp.csr_array((dd.ravel(), (rows.ravel(), cols.ravel())), shape=(p.size, p.size))
    rest = np.r_[np.zeros(3 * n), np.ones(p.size - 3 * n)]
    return (xx + sp.diags_array(rest)) @ P


class Setup:
    """A linearised problem with the solver's projection, scaling and both preconditioners."""

    def __init__(
        self, cost: JointCost, theta: np.ndarray, mask: np.ndarray, normal: bool, hops: int | None
    ):
        """``hops``: patch seeds that many edges apart; None: the position block (AMG)."""
        p = cost.p
        self.p, self.mask = p, mask
        X = p.unpack(theta)[0]
        self.directions = vertex_normals(X, p.faces)[0] if normal else None
        self.P = _projection(p, mask, self.directions)
        self.lin = cost.linearise(theta)
        self.blocks = self.lin.diagonal_blocks()
        diag = _diagonal(cost, *self.blocks)
        self.scale = np.clip(diag, 1e-6 * float(np.mean(diag[mask])), None)
        free = np.any(mask[p.slices()[0]].reshape(-1, 3), axis=1)
        bumps = None if hops is None else patch_bumps(p.faces, X, free, hops)
        self.coarse = CoarseOperator(self.lin, bumps, mask, self.scale, self.directions)

    def op(self, lam: float):  # type: ignore[no-untyped-def]
        P = self.P
        return lambda v: P @ (self.lin.matvec(P @ v) + lam * self.scale * (P @ v))

    def block(self, lam: float):  # type: ignore[no-untyped-def]
        pre = ArrowheadPreconditioner(
            self.lin, self.blocks, lam, self.scale, self.mask, self.directions
        )
        return lambda v: self.P @ pre(self.P @ v)

    def two_level(self, lam: float):  # type: ignore[no-untyped-def]
        return self.coarse.preconditioner(lam, self.block(lam))


@pytest.mark.parametrize(
    ("mode", "images", "normal", "hops"),
    [
        ("offset", False, True, 2),
        ("offset", True, True, 2),
        ("free", False, False, 2),
        ("free", True, True, 2),
        ("offset", True, True, None),
        ("free", True, False, None),
    ],
)
def test_coarse_operator_is_the_projected_normal_matrix_on_the_coarse_space(
    scene: SyntheticScene,
    image_scene: SyntheticScene,
    mode: str,
    images: bool,
    normal: bool,
    hops: int | None,
) -> None:
    cost, theta = cost_at(image_scene if images else scene, images, mode)
    p = cost.p
    mask = p.mask(True, True, True)
    mask[3 * np.arange(0, p.n_vertices, 7)[:, None] + np.arange(3)] = False  # some fixed
    if mode == "free":
        mask[p.slices()[2].start + np.arange(3)] = False  # one view's light fixed
    s = Setup(cost, theta, mask, normal, hops)
    J = cost.jacobian(theta)
    lam = 0.3
    R = s.coarse.R.toarray()
    assert R.shape[1] > 20
    assert np.allclose(s.P @ R, R, rtol=0, atol=1e-14)  # the coarse motions are allowed steps
    AR = s.P @ (J.T @ (J @ R) + lam * s.scale[:, None] * R)
    got = s.coarse.columns(lam).toarray()
    assert np.abs(got - AR).max() <= 1e-10 * np.abs(AR).max()
    pinned = np.all(R == 0, axis=0)  # coarse unknowns of fixed vertices: 1 on the diagonal
    Ac = R.T @ AR + np.diag(pinned * 1.0)
    assert np.abs(s.coarse.coarse_matrix(lam).toarray() - Ac).max() <= 1e-10 * np.abs(Ac).max()
    if hops is None:  # every free vertex's height (or x, y, z) is a coarse unknown
        free = np.count_nonzero(mask[p.slices()[0]].reshape(-1, 3).any(axis=1))
        assert np.count_nonzero(~pinned) == free * (1 if normal else 3)


@pytest.mark.parametrize(("normal", "hops"), [(True, 1), (False, 1), (True, None), (False, None)])
def test_two_level_preconditioner_is_symmetric_positive_definite(
    normal: bool, hops: int | None
) -> None:
    sc = make_scene(subdivisions=2, n_views=6, seed=4)
    problem = build_problem(sc.input(), sc.vertices, sc.light_offset[None], OptimiseSettings())
    theta = problem.pack(perturb(sc, 0.001), sc.alpha, sc.light_offset)
    mask = problem.mask(True, True, True)
    s = Setup(JointCost(problem), theta, mask, normal, hops)
    # The allowed steps: a basis of the projection's range.
    w, V = np.linalg.eigh(s.P.toarray())
    U = V[:, w > 0.5]
    apply = s.two_level(1e-3)
    M = U.T @ np.column_stack([apply(u) for u in U.T])
    assert np.abs(M - M.T).max() <= 1e-10 * np.abs(M).max()
    assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() > 0
    # and it is not the block preconditioner alone (compared on B's diagonal scale)
    B = U.T @ np.column_stack([s.block(1e-3)(u) for u in U.T])
    d = np.sqrt(np.diag(B))
    assert np.abs((M - B) / np.outer(d, d)).max() > 0.1


@pytest.fixture(scope="module")
def mid_scene() -> SyntheticScene:
    """2562 vertices: enough for the block preconditioner's slow modes to show."""
    return make_scene(subdivisions=4, n_views=8)


@pytest.mark.parametrize(("hops", "share"), [(3, 0.6), (None, 0.3)])
def test_two_level_needs_far_fewer_cg_iterations(
    mid_scene: SyntheticScene, hops: int | None, share: float
) -> None:
    start = perturb(mid_scene, 0.001)
    problem = build_problem(
        mid_scene.input(start), start, mid_scene.light_offset[None], OptimiseSettings()
    )
    theta = problem.pack(start, mid_scene.alpha, mid_scene.light_offset)
    s = Setup(JointCost(problem), theta, problem.mask(True, True, True), True, hops)
    g = -(s.P @ s.lin.gradient())
    lam = 1e-3
    _, block = _pcg(s.op(lam), g, s.block(lam), 1e-2, 500)
    _, two = _pcg(s.op(lam), g, s.two_level(lam), 1e-2, 500)
    assert block >= 30  # the problem is one where the block preconditioner struggles
    assert two <= share * block  # measured: 60 → 21 (patches), 60 → 9 (position block, AMG)


def test_solve_with_two_level_reaches_the_block_solve_cost(scene: SyntheticScene) -> None:
    start = perturb(scene, 0.001)
    problem = build_problem(scene.input(start), start, scene.light_offset[None], OptimiseSettings())
    theta = problem.pack(start, scene.alpha, scene.light_offset)
    normals = vertex_normals(start, scene.faces)[0]
    costs, cg = {}, {}
    for name in ("block", "two_level", "amg"):
        cfg = SolverSettings(
            max_iterations=300,
            function_tolerance=1e-12,
            cg_max_iterations=500,  # capped at 50, the block one stalls above the minimum
            preconditioner=name,
            coarse_hops=2,
        )
        mask = problem.mask(True, True, True)
        result = levenberg_marquardt(JointCost(problem), theta, mask, cfg, directions=normals)
        costs[name] = result.terms["total"]
        cg[name] = sum(h.cg_iterations for h in result.history)
    for name in ("two_level", "amg"):
        assert costs[name] == pytest.approx(costs["block"], rel=1e-6)
        assert cg[name] < cg["block"]
    assert costs["block"] < 0.5 * JointCost(problem).terms(theta)["total"]


def test_settings_name_the_preconditioner() -> None:
    cfg = OptimiseSettings.from_mapping(
        {"solver": {"preconditioner": "two_level", "coarse_hops": 3}}
    )
    assert cfg.solver.preconditioner == "two_level" and cfg.solver.coarse_hops == 3
    assert (
        OptimiseSettings.from_mapping({"solver": {"preconditioner": "amg"}}).solver.preconditioner
        == "amg"
    )
    with pytest.raises(RigError, match="preconditioner"):
        OptimiseSettings.from_mapping({"solver": {"preconditioner": "multigrid"}})
    with pytest.raises(RigError, match="coarse_hops"):
        OptimiseSettings.from_mapping({"solver": {"coarse_hops": 0}})
