"""The Gauss–Newton system of :class:`~reconstruct.optimise.cost.JointCost` at one θ in
factored form, and its products: what the solver's CG and preconditioner use, never forming J."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from reconstruct.optimise.kernels.normal_equations import (
    gram_products,
    lower_products,
    vertex_diagonal_blocks,
)

if TYPE_CHECKING:
    from reconstruct.optimise.cost import Geometry, JointCost

_NO_BLOCKS = np.empty((0, 3, 3))  # positions fixed: no normal Jacobian
_NO_GEOMETRIC = np.empty((0, 3))
_NO_JDX = np.empty(0)  # no geometric rows in a product


@dataclass
class Linearisation:
    """JᵀJ and Jᵀr at one θ in factored form: per vertex the k×k gram over u = [δx, δn, δα]
    (k = 6 + N_b; kept as its 6 position rows and K α×α weights), the vertex–light coupling
    and the light's own blocks. A product costs O(N k) plus the sparse normal and smoothness
    operators, never forming J."""

    cost: JointCost
    theta: np.ndarray
    terms: dict[str, float]
    geometry: Geometry
    A: np.ndarray
    # per-vertex G = Σ A_oᵀA_o over u by its position rows (N, 6, k); its α×α block is
    # Σ_k shading2[:, k] QᵀQ_k (N, K) (accumulate_normal_equations)
    gram: np.ndarray
    shading2: np.ndarray
    grad_u: np.ndarray  # (N, k)
    coupling: np.ndarray | sp.csr_array  # u × light: (N, k, 3) shared offset; sparse (N·k, 3V)
    light_block: np.ndarray  # light × light, (n_light/3, 3, 3)
    light_grad: np.ndarray  # (n_light/3, 3)
    # the normal Jacobian's and the geometric term's blocks column by column, for the
    # transposed products (empty: positions fixed, see linearise)
    dn_t_blocks: np.ndarray = field(init=False)
    jg_t_blocks: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        geo, order = self.geometry, self.cost.normal_jacobian.transpose_block
        self.dn_t_blocks = _NO_BLOCKS if geo.dn is None else np.take(geo.dn.data, order, axis=0)
        self.jg_t_blocks = (
            _NO_GEOMETRIC if geo.jg_blocks is None else np.take(geo.jg_blocks, order, axis=0)
        )

    def _back(self, yu: np.ndarray, dA: np.ndarray, jdx: np.ndarray) -> np.ndarray:
        """A θ-shaped vector with ``liftᵀ yu`` (N, k) back in x (N, 3) and α (N, N_b), plus the
        smoothness terms' α rows at ``dA`` and ``J_gᵀ jdx`` (jdx = J_g δx; empty: none)
        (:func:`lower_products`); its light part is left for the caller."""
        c, nj = self.cost, self.cost.normal_jacobian
        lap = c.laplacian
        out = np.empty(self.theta.size)
        ox, oa, _ = c.p.unpack(out)
        lower_products(
            yu,
            dA,
            nj.transpose_indptr,
            nj.transpose_row,
            self.dn_t_blocks,
            self.jg_t_blocks,
            jdx,
            lap.indptr,
            lap.indices,
            lap.data,
            c.gamma[0] * c.SS,
            c.BB,
            ox,
            oa,
        )
        return out

    def gradient(self) -> np.ndarray:
        """Jᵀr (half the gradient of E): the rendering rows lowered like a product's, the
        smoothness terms' α rows at α itself, the geometric rows ``J_gᵀ r_g``."""
        geo, sx, _, sl = self.geometry, *self.cost.p.slices()
        out = self._back(self.grad_u, np.ascontiguousarray(self.A), _NO_JDX)
        if geo.jg is not None:
            out[sx] += geo.jg.T @ geo.rg
        out[sl] = self.light_grad.ravel()
        return out

    def matvec(self, delta: np.ndarray) -> np.ndarray:
        """JᵀJ δ (two compiled passes over the vertices: lift and gram, then back)."""
        c = self.cost
        dX, dA, dL = c.p.unpack(delta)
        dX, dA = np.ascontiguousarray(dX), np.ascontiguousarray(dA)
        nj, geo = c.normal_jacobian, self.geometry
        k = self.gram.shape[2]
        dn_blocks = _NO_BLOCKS if geo.dn is None else geo.dn.data
        shared = isinstance(self.coupling, np.ndarray)
        jg = _NO_GEOMETRIC if geo.jg_blocks is None else geo.jg_blocks
        u, yu, yl, jdx = gram_products(
            self.gram,
            self.shading2,
            c.Q,
            dX,
            dA,
            nj.indptr,
            nj.block_col,
            dn_blocks,
            jg,
            self.coupling if shared else np.empty((0, k, 3)),
            dL[0],
        )
        if not isinstance(self.coupling, np.ndarray):
            yu += (self.coupling @ dL.ravel()).reshape(u.shape)
            yl = (self.coupling.T @ u.ravel()).reshape(-1, 3)
        out = self._back(yu, dA, jdx)
        out[c.p.slices()[2]] = (yl + np.einsum("lab,lb->la", self.light_block, dL)).ravel()
        return out

    def diagonal_blocks(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact diagonal blocks of JᵀJ: per vertex over [x (3), α (N_b)] and per light block
        (3×3) — the preconditioner and the Marquardt scaling."""
        c, nj = self.cost, self.cost.normal_jacobian
        blk = vertex_diagonal_blocks(
            self.gram,
            self.shading2,
            c.QtQ,
            c.gamma[0] * c.SS,
            c.lap_diag,
            c.BB,
            self.dn_t_blocks,
            self.jg_t_blocks,
            nj.transpose_indptr,
            nj.transpose_row,
        )
        return blk, self.light_block.copy()

    def light_coupling(self) -> np.ndarray | sp.csr_array:
        """Vertex-block × light block of JᵀJ over [x, α] for the preconditioner: dense
        (N, 3+N_b, 3) for the shared offset, sparse (N·(3+N_b), n_light) for free lights.

        Exact for α and for x through its own normal; a vertex's pull on its neighbours'
        normals is left out, as the vertex blocks leave out the vertex–vertex coupling (with
        it the bordered approximation is inconsistent and CG takes worse steps)."""
        c = self.cost
        n = c.p.n_vertices
        cu = self.coupling
        k = 6 + c.p.n_basis
        dn = self.geometry.dn
        dii = np.zeros((n, 3, 3)) if dn is None else dn.data[c.normal_jacobian.diagonal_block]
        # [x, α] rows from u = [x, n, α] rows: x + D_iiᵀ n, and α.
        if isinstance(cu, np.ndarray):
            out = np.empty((n, k - 3, 3))
            out[:, :3] = cu[:, :3] + dii.transpose(0, 2, 1) @ cu[:, 3:6]
            out[:, 3:] = cu[:, 6:]
            return out
        lower = np.zeros((n, 3 + k - 6, k))
        lower[:, :3, :3] = np.eye(3)
        lower[:, :3, 3:6] = dii.transpose(0, 2, 1)
        lower[:, 3:, 6:] = np.eye(k - 6)
        bsr = sp.bsr_array(
            (lower, np.arange(n), np.arange(n + 1)),
            shape=(n * (k - 3), n * k),
            blocksize=lower.shape[1:],
        )
        return (bsr @ cu).tocsr()
