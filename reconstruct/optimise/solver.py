"""Levenberg–Marquardt with an inexact, preconditioned conjugate-gradient inner solve.

Each iteration solves ``(JᵀJ + λ D) δ = −Jᵀr`` (D = diag JᵀJ, Marquardt scaling) with CG on
the factored JᵀJ of :class:`~reconstruct.optimise.cost.Linearisation`, preconditioned by the
exact diagonal blocks (per vertex [x, α], per light 3×3) — never forming J. Steps are accepted by
the gain ratio and λ follows Nielsen's update. Parameters outside a stage's mask stay fixed.

With reflectance bounds (projected Levenberg–Marquardt), a trial step that takes a vertex's
spectrum ``B α`` out of them is projected back in the metric of the vertex's damped α block:
the minimiser of the vertex's own quadratic model within the bounds, which a Euclidean
projection is not where the data constrain some basis directions far more than others.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

from calibration.bounds import ROUND_OFF, bounded_quadratic, violation
from core.config import bounded
from reconstruct.optimise.cost import JointCost
from reconstruct.optimise.kernels.cg import cg_direction, cg_step, project_to_stage
from reconstruct.optimise.kernels.preconditioner import (
    back_substitute_light,
    coupling_transpose_product,
    damped_block_inverses,
    eliminate_shared_light,
    expand_positions,
    solve_vertex_blocks,
)
from reconstruct.optimise.linearisation import Linearisation

_NO_DIRECTIONS = np.empty((0, 3))  # free motion
_NO_DAMPING = np.empty(0)


@dataclass
class SolverSettings:
    max_iterations: int = bounded(30, min=0, max=10_000)
    # stop when a step lowers the cost by less than this share
    function_tolerance: float = bounded(1e-4, min=0.0, max=1.0)
    # Stop when a step is rejected right after one that lowered the cost by less than this
    # share: the model no longer predicts the cost, and a retry costs a CG solve for less.
    stall_tolerance: float = bounded(2e-3, min=0.0, max=1.0)
    step_tolerance: float = bounded(1e-9, min=0.0, max=1.0)  # stop when |δ| <= tol · (|θ| + tol)
    initial_lambda: float = bounded(1e-3, min=0.0, max=1e12)
    # inner solve relative residual (CG is cheap next to linearising)
    cg_tolerance: float = bounded(1e-2, min=0.0, max=1.0)
    cg_max_iterations: int = bounded(50, min=1, max=100_000)
    # halvings of a rejected step tried before λ grows
    backtracking_steps: int = bounded(2, min=0, max=100)


@dataclass
class IterationRecord:
    iteration: int
    terms: dict[str, float]
    step_norm: float
    lam: float
    cg_iterations: int
    accepted: bool
    seconds: float


@dataclass
class SolveResult:
    theta: np.ndarray
    terms: dict[str, float]
    history: list[IterationRecord] = field(default_factory=list)
    stop_reason: str = ""


Callback = Callable[[IterationRecord], None]


class ArrowheadPreconditioner:
    """Exact inverse of the block diagonal of ``JᵀJ + λD`` (per vertex [x, α], per light 3×3)
    bordered by the vertex–light coupling: every vertex sees the shared light, which a plain
    block-Jacobi misses (the slow mode is the light distance against the reflectance scale).
    The light is eliminated by its small dense Schur complement.

    With ``directions`` the vertex blocks are those of the projected system, over [h, α] with
    x = h d: the projection of the 3-D block's inverse is not the inverse of the projected
    block, and where a vertex's x-block is anisotropic off its normal the two differ by large
    factors (CG then needed 10 iterations even where λD dominates)."""

    def __init__(
        self,
        lin: Linearisation,
        blocks: tuple[np.ndarray, np.ndarray],
        lam: float,
        scale: np.ndarray,
        mask: np.ndarray,
        directions: np.ndarray | None = None,
    ):
        p = lin.cost.p
        self.p = p
        self.mask = mask
        vert, light = blocks
        n, nb = p.n_vertices, p.n_basis
        sx, sa, sl = p.slices()
        # Per vertex the map from the block's position unknowns (x or h) to x, masked.
        raw = np.eye(3)[None] if directions is None else directions[:, :, None]
        self.shapes = np.ascontiguousarray(raw * mask[sx].reshape(n, 3, 1))
        m = self.shapes.shape[2]
        dv = np.concatenate([scale[sx].reshape(n, 3), scale[sa].reshape(n, nb)], axis=1)
        self.alpha_mask = mask[sa].reshape(n, nb).astype(float)
        self.vert = damped_block_inverses(vert, lam * dv, self.shapes, self.alpha_mask)
        ml = mask[sl]
        dense = np.zeros((p.n_light, p.n_light))
        for j in range(light.shape[0]):
            dense[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] = light[j]
        dense *= ml[:, None] & ml[None, :]
        dense[np.arange(p.n_light), np.arange(p.n_light)] += lam * scale[sl] + ~ml
        coupling = lin.light_coupling()
        k = m + nb
        if isinstance(coupling, np.ndarray):  # shared offset: dense (N, k, 3)
            reduced, dinv_c, schur_terms = eliminate_shared_light(
                self.vert, coupling, self.shapes, self.alpha_mask, ml.astype(float)
            )
            self.coupling: np.ndarray | sp.csr_array = reduced.reshape(n * k, 3)
            self.dinv_c: np.ndarray | sp.csr_array = dinv_c.reshape(n * k, 3)
            schur = dense - schur_terms.sum(axis=0)
        else:  # per vertex the map from [x or h, α] to [x, α]
            basis = np.zeros((n, 3 + nb, k))
            basis[:, :3, :m] = self.shapes
            basis[:, 3:, m:] = np.eye(nb) * self.alpha_mask[:, :, None]
            reduce = sp.bsr_array(
                (basis.transpose(0, 2, 1), np.arange(n), np.arange(n + 1)),
                shape=(n * k, n * (3 + nb)),
                blocksize=(k, 3 + nb),
            )
            coupling = reduce @ coupling @ sp.diags_array(ml.astype(float))
            self.coupling = coupling.tocsr()
            dinv = sp.bsr_array(
                (self.vert, np.arange(n), np.arange(n + 1)), shape=(n * k, n * k), blocksize=(k, k)
            )
            self.dinv_c = (dinv @ self.coupling).tocsr()
            schur = dense - (self.coupling.T @ self.dinv_c).toarray()
        self.schur_inv = np.linalg.inv(schur)

    def __call__(self, v: np.ndarray) -> np.ndarray:
        """The preconditioned vector; already in the stage's subspace (masked, along the
        directions), so the solver need not project it again."""
        p = self.p
        n, nb = p.n_vertices, p.n_basis
        sx, sa, sl = p.slices()
        zu = solve_vertex_blocks(self.vert, self.shapes, v[sx].reshape(n, 3), v[sa].reshape(n, nb))
        if isinstance(self.dinv_c, np.ndarray):  # shared light: dense couplings, compiled
            k = zu.shape[1]
            coupling = self.coupling.reshape(n, k, 3)
            zl = self.schur_inv @ (v[sl] - coupling_transpose_product(coupling, zu))
            out = np.empty_like(v)
            back_substitute_light(
                zu,
                self.dinv_c.reshape(n, k, 3),
                zl,
                self.shapes,
                self.alpha_mask,
                out[sx].reshape(n, 3),
                out[sa].reshape(n, nb),
            )
            out[sl] = zl * self.mask[sl]
            return out
        zl = self.schur_inv @ (v[sl] - self.coupling.T @ zu.ravel())
        zu -= (self.dinv_c @ zl).reshape(zu.shape)
        zx = expand_positions(self.shapes, zu)
        return p.pack(zx, zu[:, self.shapes.shape[2] :], zl) * self.mask


def _pcg(
    matvec: Callable[[np.ndarray], np.ndarray],
    b: np.ndarray,
    precond: Callable[[np.ndarray], np.ndarray],
    tol: float,
    max_iter: int,
) -> tuple[np.ndarray, int]:
    x = np.zeros_like(b)
    r = b.copy()
    z = precond(r)
    d = z.copy()
    rz = float(r @ z)
    target = tol * np.linalg.norm(b)
    for k in range(1, max_iter + 1):
        q = matvec(d)
        dq = float(d @ q)
        if dq <= 0:
            return x, k
        step = rz / dq
        if np.sqrt(cg_step(x, r, d, q, step)) <= target:
            return x, k
        z = precond(r)
        rz_new = float(r @ z)
        cg_direction(d, z, rz_new / rz)
        rz = rz_new
    return x, max_iter


_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc mallopt parameters
_GLIBC_DEFAULT = 128 * 1024


def _glibc() -> ctypes.CDLL | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return libc if hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


@contextmanager
def keep_freed_memory() -> Iterator[None]:
    """Keep large freed blocks in the heap while the block runs (glibc only; else a no-op).

    glibc hands every freed block above its mmap threshold back to the kernel, so each
    iteration's fresh (observations × ·) temporaries would be page-faulted in again.
    Afterwards the defaults are restored and the kept memory is trimmed, so the process
    shrinks back.
    """
    libc = _glibc()
    if libc is None:
        yield
        return
    libc.mallopt(_M_MMAP_THRESHOLD, 1 << 30)
    libc.mallopt(_M_TRIM_THRESHOLD, (1 << 31) - 1)
    try:
        yield
    finally:
        libc.mallopt(_M_TRIM_THRESHOLD, _GLIBC_DEFAULT)
        libc.mallopt(_M_MMAP_THRESHOLD, _GLIBC_DEFAULT)
        libc.malloc_trim(0)


def levenberg_marquardt(
    cost: JointCost,
    theta: np.ndarray,
    mask: np.ndarray,
    settings: SolverSettings | None = None,
    callback: Callback | None = None,
    directions: np.ndarray | None = None,
    constrain: Callable[[np.ndarray], np.ndarray] | None = None,
    reflectance_bounds: tuple[float, float] | None = None,
) -> SolveResult:
    """:func:`_levenberg_marquardt` with BLAS held to one thread and freed memory kept.

    The CG loop is made of short dot products and vectorised gathers where OpenBLAS's thread
    hand-off costs more than it gains (bench/solver.py, --blas-threads). See
    :func:`keep_freed_memory`.
    """
    with threadpool_limits(limits=1, user_api="blas"), keep_freed_memory():
        return _levenberg_marquardt(
            cost, theta, mask, settings, callback, directions, constrain, reflectance_bounds
        )


def _levenberg_marquardt(
    cost: JointCost,
    theta: np.ndarray,
    mask: np.ndarray,
    settings: SolverSettings | None,
    callback: Callback | None,
    directions: np.ndarray | None,
    constrain: Callable[[np.ndarray], np.ndarray] | None,
    reflectance_bounds: tuple[float, float] | None,
) -> SolveResult:
    """Minimise the joint cost over the parameters where ``mask`` is True.

    With ``directions`` (N, 3 unit vectors) each vertex moves only along its direction
    (its normal): steps are projected with ``P = n nᵀ`` per vertex and CG runs on that subspace
    (operator ``P H P``; the block preconditioner inverts the projected blocks). ``constrain``
    maps a trial θ into the feasible set (the vertices' trust regions); the model's prediction
    is of the step taken. ``reflectance_bounds`` (lower, upper) keeps every ``B α`` inside
    (module docstring); θ must start inside.
    """
    cfg = settings or SolverSettings()
    theta = np.array(theta, dtype=float)
    mask = np.ascontiguousarray(mask, dtype=bool)
    sx = cost.p.slices()[0]
    along = _NO_DIRECTIONS if directions is None else np.ascontiguousarray(directions, dtype=float)

    def project(v: np.ndarray) -> np.ndarray:
        out = np.array(v, dtype=float)
        project_to_stage(out, _NO_DAMPING, _NO_DAMPING, mask, along)
        return out

    positions = bool(mask[sx].any())  # else the position derivatives are left out
    lin = cost.linearise(theta, positions)
    blocks = lin.diagonal_blocks()
    lam, nu = cfg.initial_lambda, 2.0
    last_gain = np.inf  # share of the cost the last accepted step removed
    history: list[IterationRecord] = []
    reason = "maximum iterations"
    for it in range(1, cfg.max_iterations + 1):
        t0 = time.perf_counter()
        g = project(lin.gradient())
        diag = _diagonal(cost, *blocks)
        scale = np.clip(
            diag, 1e-6 * max(float(np.mean(diag[mask])) if mask.any() else 1.0, 1e-30), None
        )
        if not np.any(g):
            reason = "zero gradient"
            break
        pre = ArrowheadPreconditioner(lin, blocks, lam, scale, mask, directions)

        # CG's vectors stay in the stage's subspace (its right-hand side and the
        # preconditioner's output are projected), so only the product leaves it.
        def op(
            v: np.ndarray, lin: Linearisation = lin, damping: np.ndarray = lam * scale
        ) -> np.ndarray:
            out = lin.matvec(v)
            project_to_stage(out, damping, v, mask, along)
            return out

        delta, cg_it = _pcg(op, -g, pre, cfg.cg_tolerance, cfg.cg_max_iterations)
        del pre, op  # rebuilt next iteration; not held beside the trial render
        gd, dhd = float(g @ delta), float(delta @ lin.matvec(delta))
        # A step the model over-trusted is first shortened along the same direction (a
        # `terms` evaluation each) before λ grows and CG solves again: rejected steps are
        # mostly only somewhat too long, and an evaluation costs far less than a CG solve.
        for shorten in range(cfg.backtracking_steps + 1):
            fraction = 0.5**shorten
            predicted = -(2.0 * fraction * gd + fraction**2 * dhd)
            trial = theta + fraction * delta
            if constrain is not None or reflectance_bounds is not None:
                if constrain is not None:
                    trial = constrain(trial)
                if reflectance_bounds is not None:
                    trial = _within_bounds(
                        cost, trial, theta, blocks[0], lam * scale, reflectance_bounds
                    )
                taken = trial - theta
                if not np.allclose(taken, fraction * delta, rtol=0.0, atol=1e-15):
                    predicted = -(2.0 * float(g @ taken) + float(taken @ lin.matvec(taken)))
            terms = cost.terms(trial, positions)
            actual = lin.terms["total"] - terms["total"]
            accepted = bool(np.isfinite(terms["total"]) and actual > 0 and predicted > 0)
            if accepted:
                break
        step = float(np.linalg.norm(trial - theta if accepted else delta))
        if accepted:
            rho = actual / predicted
            # a shortened step says the damping was too low: raise it as a rejection would
            shrink = max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            lam *= shrink if fraction == 1.0 else 1.0
            nu = 2.0
            previous = lin.terms["total"]
            last_gain = actual / previous if previous > 0 else 0.0
            theta = trial
            # the old system's blocks go before the new ones are built
            del lin, blocks
            lin = cost.linearise(theta, positions)
            blocks = lin.diagonal_blocks()
        else:
            lam *= nu
            nu *= 2.0
        record = IterationRecord(
            it, dict(lin.terms), step, lam, cg_it, accepted, time.perf_counter() - t0
        )
        history.append(record)
        if callback:
            callback(record)
        # (a shortened step's small gain says the full step was too long, not convergence)
        if accepted and fraction == 1.0 and actual <= cfg.function_tolerance * previous:
            reason = "cost change below tolerance"
            break
        if not accepted and last_gain < cfg.stall_tolerance:
            reason = "stalled (a step rejected after a gain below the stall tolerance)"
            break
        if step <= cfg.step_tolerance * (np.linalg.norm(theta * mask) + cfg.step_tolerance):
            reason = "step below tolerance"
            break
        if lam > 1e12:
            reason = "damping diverged (no descent direction)"
            break
    return SolveResult(theta, dict(lin.terms), history, reason)


def _diagonal(cost: JointCost, vert: np.ndarray, light: np.ndarray) -> np.ndarray:
    p = cost.p
    d = np.diagonal(vert, axis1=1, axis2=2)
    dl = np.diagonal(light, axis1=1, axis2=2)
    return p.pack(d[:, :3], d[:, 3:], dl)


def _within_bounds(
    cost: JointCost,
    trial: np.ndarray,
    theta: np.ndarray,
    vert: np.ndarray,
    damping: np.ndarray,
    bounds: tuple[float, float],
) -> np.ndarray:
    """``trial`` with each vertex's α that leaves the bounds replaced by the minimiser, within
    them, of ``(α − α_trial)ᵀ M (α − α_trial)``, M the vertex's damped α block of the system
    the step solved; ``theta`` (inside the bounds) is each row's start."""
    p = cost.p
    n, nb = p.n_vertices, p.n_basis
    sa = p.slices()[1]
    a = trial[sa].reshape(n, nb)
    rows = np.flatnonzero(violation(a, cost.B, *bounds) > ROUND_OFF)
    if rows.size == 0:
        return trial
    metric = vert[rows, 3:, 3:] + damping[sa].reshape(n, nb)[rows, :, None] * np.eye(nb)
    # a vertex no term constrains yet (no observation, no edge) still gets a definite metric
    metric += 1e-12 * np.trace(metric, axis1=1, axis2=2).max() * np.eye(nb)
    out = trial.copy()
    inside = bounded_quadratic(
        metric,
        np.einsum("nij,nj->ni", metric, a[rows]),
        cost.B,
        *bounds,
        start=theta[sa].reshape(n, nb)[rows],
        unconstrained=a[rows],
    )
    out[sa.start + (rows[:, None] * nb + np.arange(nb)).ravel()] = inside.ravel()
    return out
