"""Two-level preconditioner for the Levenberg–Marquardt inner solve: a coarse-space correction
on top of the per-vertex block preconditioner.

Why: the block preconditioner inverts each vertex's own [x, α] block exactly but cannot see the
vertex–vertex coupling through the normals: shading and the geometric term make the position
Hessian a 2nd/4th-order operator on the mesh, whose smooth modes (a patch of vertices moving
together) a per-vertex block barely damps. A coarse space of smooth per-patch motions
captures those (bench/README.md, solver: what it gains and what it does not).

* Patches: seeds ``hops`` edges apart (a distance-``hops`` maximal independent set of the free
  vertices), every free vertex joined to its nearest seed (Dijkstra over the edge lengths).
* Prolongation: the patch indicators smoothed by a Jacobi step of the mesh's ring mean
  (smoothed aggregation: the bumps overlap and still sum to one, so a coarse motion bends
  the surface smoothly); per patch one height along the vertices' directions (normal motion)
  or three translations (free motion).
* Coarse operator: ``A R`` exactly, ``A = P (JᵀJ + λD) P`` (P: mask and directions), assembled
  from the factored JᵀJ vertex by vertex (:func:`shape_columns`); ``A_c = Rᵀ A R`` is sparse
  and factored by LU. ``Rᵀ(λD)R`` is kept apart, so λ is added exactly; the solver builds the
  operator once per CG solve and drops it before the trial render (memory).
* Combination: balancing Neumann–Neumann, ``M⁻¹ = Q + (I − QA) B⁻¹ (I − AQ)`` with
  ``Q = R A_c⁻¹ Rᵀ`` and B⁻¹ the block preconditioner: symmetric positive definite for any SPD
  B⁻¹ and any SPD ``A_c⁻¹`` (no smoother condition), and no product with A beyond the stored
  ``A R``.
* Position block (``bumps=None``): the coarse space is every position unknown (each vertex's
  height, or its x, y, z), so ``A_c`` is the whole position block of ``P (JᵀJ + λD) P``, and an
  algebraic-multigrid V-cycle (pyamg, plain aggregation, symmetric Gauss–Seidel: an SPD
  ``A_c⁻¹``) stands in for its inverse. Why: the slow modes of the block-preconditioned
  operator are not smooth on the mesh (they sit on vertices seen by few views), so patch bumps
  miss them; the exact position block takes CG from 45 to 4 iterations, and the V-cycle keeps
  most of that (7) for a setup of ~0.1 s where a sparse LU took 2.8 s (25k vertices).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pyamg
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.sparse.linalg import splu

from reconstruct.optimise.cost import Linearisation
from reconstruct.optimise.kernels import position_columns
from reconstruct.optimise.mesh import adjacency

Apply = Callable[[np.ndarray], np.ndarray]


def _row_max(graph: sp.csr_array, values: np.ndarray, empty: float) -> np.ndarray:
    """Largest ``values`` over each row's columns (``empty`` for a row without any)."""
    out = np.full(graph.shape[0], empty)
    starts = graph.indptr[:-1]
    rows = np.flatnonzero(np.diff(graph.indptr) > 0)
    if rows.size:
        out[rows] = np.maximum.reduceat(values[graph.indices], starts[rows])
    return out


def _spread_max(ring: sp.csr_array, values: np.ndarray, hops: int) -> np.ndarray:
    """Largest value within ``hops`` edges of each vertex (``ring`` has self loops)."""
    for _ in range(hops):
        values = _row_max(ring, values, -np.inf)
    return values


def seeds(adj: sp.csr_array, hops: int, free: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Free vertices pairwise more than ``hops`` edges apart with every free vertex within
    ``hops`` of one (Luby's rounds: a vertex joins when it has the largest priority in reach)."""
    n = adj.shape[0]
    ring = (adj + sp.eye_array(n, format="csr")).tocsr()
    ring.sort_indices()
    priority = rng.permutation(n).astype(float)
    open_ = free.copy()
    chosen = np.zeros(n, dtype=bool)
    while open_.any():
        p = np.where(open_, priority, -1.0)
        new = open_ & (p == _spread_max(ring, p, hops))
        chosen |= new
        open_ &= ~(_spread_max(ring, new.astype(float), hops) > 0)
    return np.flatnonzero(chosen)


def aggregates(adj: sp.csr_array, vertices: np.ndarray, hops: int, free: np.ndarray) -> np.ndarray:
    """Patch index per vertex (−1: fixed): each free vertex joins its nearest seed along the
    edges between free vertices."""
    centres = seeds(adj, hops, free, np.random.default_rng(0))
    coo = sp.triu(adj, k=1).tocoo()
    inside = free[coo.row] & free[coo.col]
    a, b = coo.row[inside], coo.col[inside]
    length = np.maximum(np.linalg.norm(vertices[a] - vertices[b], axis=1), 1e-300)  # 0: no edge
    _, _, source = csgraph.dijkstra(
        sp.csr_array((length, (a, b)), shape=adj.shape),
        directed=False,
        indices=centres,
        min_only=True,
        return_predecessors=True,
    )
    lookup = np.full(adj.shape[0], -1, dtype=np.int64)
    lookup[centres] = np.arange(centres.size)
    return np.where(source >= 0, lookup[np.maximum(source, 0)], -1)


def smoothed_prolongation(adj: sp.csr_array, patch: np.ndarray, steps: int) -> sp.csr_array:
    """(N × patches) bumps: patch indicators after ``steps`` Jacobi steps
    ``(1 − ω) I + ω · ring mean`` (ω = 2/3) on the graph of the patched vertices. Their rows
    keep summing to one; unpatched (fixed) vertices stay out."""
    n = adj.shape[0]
    inside = sp.diags_array((patch >= 0).astype(float))
    adj = inside @ adj @ inside
    deg = np.asarray(adj.sum(axis=1)).ravel()
    omega = np.where(deg > 0, 2.0 / 3.0, 0.0)
    smoother = sp.diags_array(1.0 - omega) + sp.diags_array(omega / np.maximum(deg, 1.0)) @ adj
    rows = np.flatnonzero(patch >= 0)
    s = sp.csr_array((np.ones(rows.size), (rows, patch[rows])), shape=(n, int(patch.max()) + 1))
    for _ in range(steps):
        s = smoother @ s
    return s.tocsr()


def patch_bumps(
    faces: np.ndarray, vertices: np.ndarray, free: np.ndarray, hops: int, smoothing: int = 1
) -> sp.csr_array:
    """The coarse space of one stage's mesh: smoothed bumps (N × patches) over patches of the
    ``free`` vertices (the fixed ones are in none)."""
    adj = adjacency(faces, len(vertices))
    return smoothed_prolongation(adj, aggregates(adj, vertices, hops, free), smoothing)


def _bsr(blocks: np.ndarray, cols: np.ndarray, indptr: np.ndarray, n_cols: int) -> sp.csr_array:
    """CSR of a block-sparse matrix with ``blocks`` (B, r, c) in block columns ``cols``."""
    r, c = blocks.shape[1:]
    shape = ((len(indptr) - 1) * r, n_cols * c)
    return sp.bsr_array((blocks, cols, indptr), shape=shape, blocksize=(r, c)).tocsr()


def shape_columns(lin: Linearisation, shapes: np.ndarray) -> sp.csr_array:
    """``JᵀJ Φ`` in reduced rows: JᵀJ's columns along every vertex's motion shapes Φ_i
    (N, 3, m), rows [Φᵀx (m·N), α (N·N_b), light], assembled vertex by vertex from the
    factored form (:func:`~reconstruct.optimise.kernels.position_columns`: a vertex's shapes
    move its own x and its ring's normals) on the normal Jacobian's cached 2-ring pattern.
    Measured at 100k vertices (normal motion): 1.8 s by sparse matrix products, 0.3 s so."""
    c = lin.cost
    p = c.p
    n, nb = p.n_vertices, p.n_basis
    nj = c.normal_jacobian
    geo = lin.geometry
    assert geo.dn is not None and geo.jg_blocks is not None, "needs the position derivatives"
    m = shapes.shape[2]
    pair_indptr, pair_indices, offsets, slots = nj.ring_pairs
    cu = lin.coupling
    shared = isinstance(cu, np.ndarray)
    hh, ah, light_rows = position_columns(
        lin.gram,
        np.ascontiguousarray(shapes, dtype=float),
        nj.indptr,
        nj.block_col,
        np.ascontiguousarray(geo.dn.data),
        geo.jg_blocks,
        offsets,
        slots,
        pair_indices.size,
        cu if shared else np.empty((0, 6 + nb, 3)),
    )
    shape = (m * n, m * n)
    xx = sp.bsr_array((hh, pair_indices, pair_indptr), shape=shape, blocksize=(m, m)).tocsr()
    ax = _bsr(ah, nj.block_col, nj.indptr, n)
    if shared:
        light = sp.csr_array(light_rows.reshape(3, m * n))
    else:  # per-view lights: the sparse coupling's x and n rows along Φ and ∂n/∂X Φ
        diag, ids = np.arange(n), np.arange(n + 1)
        E = _bsr(geo.dn.data @ shapes[nj.block_col], nj.block_col, nj.indptr, n)
        base = (6 + nb) * np.arange(n)[:, None]
        light = (
            cu[(base + np.arange(3)).ravel()].T @ _bsr(shapes, diag, ids, n)
            + cu[(base + np.arange(3, 6)).ravel()].T @ E
        )
    return sp.vstack([xx, ax, light]).tocsr()


class CoarseOperator:
    """``R`` and the exact ``A R`` of one linearisation, from which :meth:`preconditioner`
    makes the two-level preconditioner for any λ.

    Coarse unknown ``m·j + b`` (patch j, shape b) moves vertex i by ``S_ij · shape_i[:, b]``:
    the direction ``d_i`` (normal motion, m = 1) or the axes (free motion, m = 3), projected
    like every step. Without ``bumps`` every vertex is its own patch (S = I) and the coarse
    matrix, the whole position block, is solved by a multigrid V-cycle instead of LU."""

    def __init__(
        self,
        lin: Linearisation,
        bumps: sp.csr_array | None,
        mask: np.ndarray,
        scale: np.ndarray,
        directions: np.ndarray | None,
    ):
        self.multigrid = bumps is None
        p = lin.cost.p
        n = p.n_vertices
        sx, sa, sl = p.slices()
        raw = np.eye(3)[None] if directions is None else directions[:, :, None]
        shapes = np.broadcast_to(raw, (n, 3, raw.shape[2])) * mask[sx].reshape(n, 3, 1)
        if directions is not None:  # as the solver projects: d dᵀ after the mask
            shapes = directions[:, :, None] * np.einsum("na,nam->nm", directions, shapes)[:, None]
        m = shapes.shape[2]
        diag, ids = np.arange(n), np.arange(n + 1)
        phi = _bsr(shapes, diag, ids, n)  # (3N, mN): x = Φ h
        # θ rows from the reduced rows [Φᵀx, α, light]; A R is kept in the reduced rows.
        self.lift = sp.block_diag(
            [phi, sp.diags_array(mask[sa] * 1.0), sp.diags_array(mask[sl] * 1.0)]
        ).tocsr()
        # P(λD)P R, added per λ: Φᵀ diag(D_x) Φ per vertex.
        dx = _bsr(shapes.transpose(0, 2, 1) @ (scale[sx].reshape(n, 3, 1) * shapes), diag, ids, n)
        columns = shape_columns(lin, shapes)
        rest = sp.csr_array((columns.shape[0] - m * n, m * n))
        if bumps is None:  # R = [Φ; 0]: no products with an identity, Rᵀ lift = [ΦᵀΦ, 0]
            self.R = self.lift[:, : m * n]
            self.HR = columns
            self.DR = sp.vstack([dx, rest]).tocsr()
            gram = _bsr(shapes.transpose(0, 2, 1) @ shapes, diag, ids, n)
            self.RtHR = gram @ columns[: m * n]
            self.RtDR = gram @ dx
            # coarse unknowns of fixed vertices move nothing: pinned, so A_c stays regular
            moves = np.abs(shapes).sum(axis=1).ravel() > 0
            self.pinned = sp.diags_array((~moves).astype(float))
        else:
            coarse = sp.kron(bumps, sp.eye_array(m), format="csr")  # (mN, m·patches)
            coarse = coarse[:, np.flatnonzero(np.asarray(abs(phi @ coarse).sum(axis=0)))]
            self.R = self.lift[:, : m * n] @ coarse
            self.HR = columns @ coarse
            self.DR = sp.vstack([dx @ coarse, rest @ coarse]).tocsr()
            Rt = self.R.T.tocsr()
            self.RtHR = Rt @ (self.lift @ self.HR)
            self.RtDR = Rt @ (self.lift @ self.DR)
            self.pinned = sp.csr_array(self.RtHR.shape)

    def columns(self, lam: float) -> sp.csr_array:
        """``A R`` in θ's rows."""
        return (self.lift @ (self.HR + lam * self.DR)).tocsr()

    def coarse_matrix(self, lam: float) -> sp.csc_array:
        """``A_c = Rᵀ P (JᵀJ + λD) P R`` (symmetrised against rounding), with 1 on the
        diagonal of coarse unknowns that move nothing (fixed vertices)."""
        a = self.RtHR + lam * self.RtDR
        return ((a + a.T) * 0.5 + self.pinned).tocsc()

    def coarse_solve(self, lam: float) -> Apply:
        """``A_c⁻¹``: exact (LU) over patches, a V-cycle over the whole position block."""
        matrix = self.coarse_matrix(lam)
        if not self.multigrid:
            return splu(matrix).solve
        # Plain aggregation with two symmetric Gauss–Seidel sweeps a side: a quarter of the
        # setup of smoothed aggregation (0.09 against 0.34 s at 100k vertices) for the same
        # CG iterations; the setup is paid once per CG solve.
        sweeps = ("gauss_seidel", {"sweep": "symmetric", "iterations": 2})
        levels = pyamg.smoothed_aggregation_solver(
            matrix.tocsr(),
            symmetry="symmetric",
            smooth=None,
            improve_candidates=None,
            presmoother=sweeps,
            postsmoother=sweeps,
        )
        return levels.aspreconditioner(cycle="V").matvec

    def preconditioner(self, lam: float, block: Apply) -> Apply:
        """Balancing Neumann–Neumann around the (projected) block preconditioner ``block``:
        ``M⁻¹ = Q + (I − QA) B⁻¹ (I − AQ)``, ``Q = R A_c⁻¹ Rᵀ``."""
        if self.R.shape[1] == 0:
            return block
        solve = self.coarse_solve(lam)
        R, lift, HR, DR = self.R, self.lift, self.HR, self.DR

        def apply(r: np.ndarray) -> np.ndarray:
            y = solve(R.T @ r)
            z = block(r - lift @ (HR @ y + lam * (DR @ y)))
            v = lift.T @ z
            return z + R @ (y - solve(HR.T @ v + lam * (DR.T @ v)))

        return apply
