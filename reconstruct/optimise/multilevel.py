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
  from the factored JᵀJ by sparse products (:func:`shape_columns`); ``A_c = Rᵀ A R`` is sparse
  and factored by LU. Between a rejected step and its retry only λ changes, and ``Rᵀ(λD)R``
  is added exactly.
* Combination: balancing Neumann–Neumann, ``M⁻¹ = Q + (I − QA) B⁻¹ (I − AQ)`` with
  ``Q = R A_c⁻¹ Rᵀ`` and B⁻¹ the block preconditioner: symmetric positive definite for any SPD
  B⁻¹ (no smoother condition), and no product with A beyond the stored ``A R``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.sparse.linalg import splu

from reconstruct.optimise.cost import Linearisation
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
    (N, 3, m), rows [Φᵀx (m·N), α (N·N_b), light], assembled from the factored form:

    ``Φᵀ H_xx Φ = ΦᵀG_xxΦ + ΦᵀG_xn E + EᵀG_nxΦ + EᵀG_nn E + (J_gΦ)ᵀ(J_gΦ)`` with
    ``E = ∂n/∂x Φ`` (a vertex's shapes move its ring's normals), ``H_αx Φ = G_αxΦ + G_αn E``
    and the light rows ``C_xᵀΦ + C_nᵀE``. Sparse products of block-diagonal and
    ring-sparse matrices (measured: 3× faster than probing the matrix-free product with
    coloured groups of patches, and faster than per-block numpy gathers)."""
    c = lin.cost
    p = c.p
    n, nb = p.n_vertices, p.n_basis
    nj = c.normal_jacobian
    geo = lin.geometry
    assert geo.dn is not None and geo.jg_blocks is not None, "needs the position derivatives"
    G = lin.gram
    diag, ids = np.arange(n), np.arange(n + 1)
    E = _bsr(geo.dn.data @ shapes[nj.block_col], nj.block_col, nj.indptr, n)  # (3N, mN)
    Phi = _bsr(shapes, diag, ids, n)  # (3N, mN): x = Φ h
    JPhi = _bsr(
        np.einsum("ba,bam->bm", geo.jg_blocks, shapes[nj.block_col])[:, None],
        nj.block_col,
        nj.indptr,
        n,
    )
    Gn = _bsr(G[:, 3:6, 3:6], diag, ids, n)
    W = _bsr(G[:, 3:6, :3] @ shapes, diag, ids, n)  # G_nx Φ, (3N, mN)
    xx = (
        _bsr(shapes.transpose(0, 2, 1) @ G[:, :3, :3] @ shapes, diag, ids, n)
        + W.T @ E
        + E.T @ (W + Gn @ E)
        + JPhi.T @ JPhi
    )
    ax = _bsr(G[:, 6:, :3] @ shapes, diag, ids, n) + _bsr(G[:, 6:, 3:6], diag, ids, n) @ E
    cu = lin.coupling
    k = 6 + nb
    if isinstance(cu, np.ndarray):  # shared offset: (N, k, 3)
        light = sp.csr_array(
            cu[:, :3].reshape(3 * n, 3).T @ Phi + cu[:, 3:6].reshape(3 * n, 3).T @ E
        )
    else:
        base = k * np.arange(n)[:, None]
        light = (
            cu[(base + np.arange(3)).ravel()].T @ Phi + cu[(base + np.arange(3, 6)).ravel()].T @ E
        )
    return sp.vstack([xx, ax, light]).tocsr()


class CoarseOperator:
    """``R`` and the exact ``A R`` of one linearisation, from which :meth:`preconditioner`
    makes the two-level preconditioner for any λ.

    Coarse unknown ``m·j + b`` (patch j, shape b) moves vertex i by ``S_ij · shape_i[:, b]``:
    the direction ``d_i`` (normal motion, m = 1) or the axes (free motion, m = 3), projected
    like every step."""

    def __init__(
        self,
        lin: Linearisation,
        bumps: sp.csr_array,
        mask: np.ndarray,
        scale: np.ndarray,
        directions: np.ndarray | None,
    ):
        self.lin = lin
        p = lin.cost.p
        n = p.n_vertices
        sx, sa, sl = p.slices()
        raw = np.eye(3)[None] if directions is None else directions[:, :, None]
        shapes = np.broadcast_to(raw, (n, 3, raw.shape[2])) * mask[sx].reshape(n, 3, 1)
        if directions is not None:  # as the solver projects: d dᵀ after the mask
            shapes = directions[:, :, None] * np.einsum("na,nam->nm", directions, shapes)[:, None]
        m = shapes.shape[2]
        diag, ids = np.arange(n), np.arange(n + 1)
        coarse = sp.kron(bumps, sp.eye_array(m), format="csr")  # (mN, m·patches)
        keep = np.flatnonzero(np.asarray(abs(_bsr(shapes, diag, ids, n) @ coarse).sum(axis=0)))
        coarse = coarse[:, keep]
        # θ rows from the reduced rows [Φᵀx, α, light]; A R is kept in the reduced rows.
        self.lift = sp.block_diag(
            [
                _bsr(shapes, diag, ids, n),
                sp.diags_array(mask[sa] * 1.0),
                sp.diags_array(mask[sl] * 1.0),
            ]
        ).tocsr()
        self.R = self.lift[:, : m * n] @ coarse
        self.HR = shape_columns(lin, shapes) @ coarse
        # P(λD)P R, added per λ: Φᵀ diag(D_x) Φ per vertex.
        dx = shapes.transpose(0, 2, 1) @ (scale[sx].reshape(n, 3, 1) * shapes)
        dr = _bsr(dx, diag, ids, n) @ coarse
        self.DR = sp.vstack([dr, sp.csr_array((self.HR.shape[0] - dr.shape[0], dr.shape[1]))])
        Rt = self.R.T.tocsr()
        self.RtHR = Rt @ (self.lift @ self.HR)
        self.RtDR = Rt @ (self.lift @ self.DR)

    def columns(self, lam: float) -> sp.csr_array:
        """``A R`` in θ's rows."""
        return (self.lift @ (self.HR + lam * self.DR)).tocsr()

    def coarse_matrix(self, lam: float) -> sp.csc_array:
        """``A_c = Rᵀ P (JᵀJ + λD) P R`` (symmetrised against rounding)."""
        a = self.RtHR + lam * self.RtDR
        return ((a + a.T) * 0.5).tocsc()

    def preconditioner(self, lam: float, block: Apply) -> Apply:
        """Balancing Neumann–Neumann around the (projected) block preconditioner ``block``:
        ``M⁻¹ = Q + (I − QA) B⁻¹ (I − AQ)``, ``Q = R A_c⁻¹ Rᵀ``."""
        if self.R.shape[1] == 0:
            return block
        solve = splu(self.coarse_matrix(lam)).solve
        R, Rt, lift, down = self.R, self.R.T.tocsr(), self.lift, self.lift.T.tocsr()
        AR = (self.HR + lam * self.DR).tocsr()  # reduced rows
        ARt = AR.T.tocsr()

        def apply(r: np.ndarray) -> np.ndarray:
            y = solve(Rt @ r)
            z = block(r - lift @ (AR @ y))
            return z + R @ (y - solve(ARt @ (down @ z)))

        return apply
