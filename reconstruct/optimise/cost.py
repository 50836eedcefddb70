"""The joint cost of the paper, eq. (1), as residuals, an exact sparse Jacobian, and the
Gauss–Newton system the solver uses.

Residual blocks (E = Σ r², the paper's cost with no ½):

* rendering (eq. 2, 12): per observation o = (vertex i, frame f), 3 channels,
  ``r_o = k (y(x_i, α_i, p_c) − y_obs(π_c(x_i))) / sqrt(|V(i)|)``; y from
  :mod:`reconstruct.forward`, y_obs sampled bilinearly at the vertex's projection (disparity cue),
  k the rendering unit (``Weights.rendering_scale``);
* spectral smoothness (eq. 14): ``sqrt(γ1) R_s α_i`` with ``R_sᵀR_s = (D B)ᵀ(D B)``;
* photometric smoothness (eq. 15): ``sqrt(2 γ2 w_ij) R_b (α_i − α_j)`` per undirected edge with
  ``R_bᵀR_b = BᵀB`` (the paper's double sum visits each edge twice);
* geometric smoothness (eq. 16): ``sqrt(γ3) n_iᵀ(x_i − x̄_i) / l_i``: distance of the vertex to the
  plane through its neighbours' centroid x̄_i with the vertex normal, over the scale l_i.

The R factors (QR of D B and B) give identical costs with N_b rows instead of N_λ. A robust loss
(Huber/Cauchy on an observation's RGB error) is applied by iteratively reweighting the rendering
residuals; :meth:`JointCost.residuals`/:meth:`jacobian` expose the plain least-squares cost so a
benchmark can hand it to ``scipy.optimize.least_squares``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.sparse as sp

from calibration.spectra import second_difference_matrix
from reconstruct.forward import render_values, shading
from reconstruct.optimise.mesh import adjacency, normal_jacobian, vertex_normals
from reconstruct.optimise.problem import Problem
from reconstruct.optimise.sampling import bilinear, project_with_jacobian

Robust = Literal["none", "huber", "cauchy"]
TERMS = ("rendering", "spectral", "photometric", "geometric")


def _r_factor(m: np.ndarray) -> np.ndarray:
    """Square R with ``RᵀR = mᵀm`` (QR of a tall matrix)."""
    return np.asarray(np.linalg.qr(m, mode="r"))


def _segment_sum(values: np.ndarray, starts: np.ndarray) -> np.ndarray:
    return np.add.reduceat(values, starts, axis=0) if len(starts) else values[:0]


@dataclass
class RenderState:
    """Per-observation quantities at one θ (derivative parts only when asked)."""

    s: np.ndarray  # shading (M,)
    colour: np.ndarray  # unit-shading rendered RGB C^T L_k B α_i (M, 3)
    error: np.ndarray  # y − y_obs (M, 3)
    g: np.ndarray | None = None  # ∂s/∂p (= −∂s/∂x with n fixed) (M, 3)
    h: np.ndarray | None = None  # ∂s/∂n (M, 3)
    obs_grad: np.ndarray | None = None  # ∂y_obs/∂x (M, 3, 3), None for fixed observations


@dataclass
class Geometry:
    normals: np.ndarray
    dn: sp.bsr_array | None
    jg: sp.csr_array | None
    rg: np.ndarray  # geometric residuals (N,)


class JointCost:
    """Residuals, Jacobian and Gauss–Newton products of eq. (1) for one :class:`Problem`."""

    def __init__(self, problem: Problem, robust: Robust = "none", robust_scale: float = 0.02):
        """``robust_scale``: the RGB error (linear image units) where the robust loss bends."""
        p = problem
        self.p = p
        self.robust = robust
        self.robust_scale = float(robust_scale)
        B = np.asarray(p.basis, dtype=float)
        self.B = B
        self.Q = np.einsum("knl,lb->knb", p.rig.responses, B)  # (K, 3, N_b)
        self.R_s = _r_factor(second_difference_matrix(B.shape[0]) @ B)
        self.R_b = _r_factor(B)
        self.SS = self.R_s.T @ self.R_s
        self.BB = self.R_b.T @ self.R_b
        self.QtQ = np.einsum("kcb,kcd->kbd", self.Q, self.Q)
        g1, g2, g3 = p.weights.gamma
        self.gamma = (float(g1), float(g2), float(g3))
        n = p.n_vertices
        adj = adjacency(p.faces, n)
        deg = np.asarray(adj.sum(axis=1)).ravel()
        self.ring_mean = sp.diags_array(1.0 / np.maximum(deg, 1.0)) @ adj
        self.umbrella = sp.kron(sp.eye_array(n) - self.ring_mean, sp.eye_array(3), format="csr")
        e = p.weights.edges
        w = 2.0 * self.gamma[1] * np.asarray(p.weights.edge_weight, dtype=float)
        self.edge_sqrt = np.sqrt(w)
        lap = sp.coo_array(
            (
                np.r_[w, w, -w, -w],
                (
                    np.r_[e[:, 0], e[:, 1], e[:, 0], e[:, 1]],
                    np.r_[e[:, 0], e[:, 1], e[:, 1], e[:, 0]],
                ),
            ),
            shape=(n, n),
        )
        self.laplacian = lap.tocsr()
        self.lap_diag = self.laplacian.diagonal()
        o = p.obs
        self.obs_weight = p.weights.rendering_scale / np.sqrt(np.maximum(o.per_vertex[o.vertex], 1))
        self.view_index = [np.flatnonzero(o.view == c) for c in range(p.rig.n_views)]
        self.light_index = np.zeros(o.count, dtype=np.int64) if p.light_mode == "offset" else o.view
        self.light_maps = p.light_maps()  # ∂p_c/∂θ_light (N_views, 3, 3)

    # --- evaluation ---------------------------------------------------------------------

    def geometry(self, X: np.ndarray, derivatives: bool) -> Geometry:
        p = self.p
        normals, _ = vertex_normals(X, p.faces)
        offset = X - self.ring_mean @ X
        k = np.sqrt(self.gamma[2]) / p.weights.scale
        rg = k * np.einsum("ij,ij->i", normals, offset)
        if not derivatives:
            return Geometry(normals, None, None, rg)
        dn = normal_jacobian(X, p.faces)
        n = p.n_vertices
        rows = np.repeat(np.arange(n), 3)
        cols = np.arange(3 * n)
        nrow = sp.csr_array(((normals * k[:, None]).ravel(), (rows, cols)), shape=(n, 3 * n))
        erow = sp.csr_array(((offset * k[:, None]).ravel(), (rows, cols)), shape=(n, 3 * n))
        jg = (nrow @ self.umbrella + erow @ dn.tocsr()).tocsr()
        return Geometry(normals, dn, jg, rg)

    def render(
        self,
        X: np.ndarray,
        A: np.ndarray,
        light: np.ndarray,
        normals: np.ndarray,
        derivatives: bool,
    ) -> RenderState:
        """Rendered vs observed RGB for every observation (the forward model of forward.py)."""
        p, o = self.p, self.p.obs
        P = p.light_positions(light)
        xo, no, po = X[o.vertex], normals[o.vertex], P[o.view]
        s = shading(xo, no, po)
        refl = A @ self.B.T
        unit = np.ones(p.n_vertices)
        colours = np.stack([render_values(refl, unit, resp) for resp in p.rig.responses])
        colour = colours[o.illumination, o.vertex]
        y = s[:, None] * colour
        obs_grad = None
        if o.fixed_rgb is not None:
            y_obs = o.fixed_rgb
        else:
            assert p.frames.images is not None
            y_obs = np.empty_like(y)
            if derivatives:
                obs_grad = np.empty((o.count, 3, 3))
            for c, idx in enumerate(self.view_index):
                if idx.size == 0:
                    continue
                uv, duv = project_with_jacobian(p.rig.intrinsics[c], p.rig.poses[c], xo[idx])
                value, grad = bilinear(p.frames.images, o.frame[idx], uv)
                y_obs[idx] = value
                if obs_grad is not None:
                    obs_grad[idx] = grad @ duv
        state = RenderState(s, colour, y - y_obs, obs_grad=obs_grad)
        if derivatives:
            d = po - xo
            dist = np.linalg.norm(d, axis=1)
            dot = np.einsum("ij,ij->i", d, no)
            lit = (s > 0)[:, None]
            inv3 = 1.0 / dist**3
            state.g = np.where(
                lit, no * inv3[:, None] - 3.0 * (dot * inv3 / dist**2)[:, None] * d, 0.0
            )
            state.h = np.where(lit, d * inv3[:, None], 0.0)
        return state

    def _robust(self, error: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """ρ(z) and the IRLS weight sqrt(ρ'(z)) of z = |e|² per observation."""
        z = np.einsum("ij,ij->i", error, error)
        if self.robust == "none":
            return z, np.ones_like(z)
        d2 = self.robust_scale**2
        if self.robust == "huber":
            root = np.sqrt(z)
            rho = np.where(z <= d2, z, 2.0 * self.robust_scale * root - d2)
            drho = np.where(z <= d2, 1.0, self.robust_scale / np.maximum(root, 1e-300))
        else:
            rho = d2 * np.log1p(z / d2)
            drho = 1.0 / (1.0 + z / d2)
        return rho, np.sqrt(drho)

    def terms(self, theta: np.ndarray) -> dict[str, float]:
        """Each term of eq. (1) (already multiplied by its γ) and the total."""
        X, A, light = self.p.unpack(theta)
        geo = self.geometry(X, derivatives=False)
        state = self.render(X, A, light, geo.normals, derivatives=False)
        return self._terms(A, geo, state)

    def _terms(self, A: np.ndarray, geo: Geometry, state: RenderState) -> dict[str, float]:
        rho, _ = self._robust(state.error)
        e = self.p.weights.edges
        diff = (A[e[:, 0]] - A[e[:, 1]]) @ self.R_b.T
        out = {
            "rendering": float(np.sum(rho * self.obs_weight**2)),
            "spectral": self.gamma[0] * float(np.sum((A @ self.R_s.T) ** 2)),
            "photometric": float(np.sum((self.edge_sqrt[:, None] * diff) ** 2)),
            "geometric": float(np.sum(geo.rg**2)),
        }
        out["total"] = sum(out[k] for k in TERMS)
        return out

    # --- plain least squares: residual vector and sparse Jacobian ----------------------

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """The residual vector r(θ) with E = Σ r² (rendering, spectral, photometric, geometric)."""
        X, A, light = self.p.unpack(theta)
        geo = self.geometry(X, derivatives=False)
        state = self.render(X, A, light, geo.normals, derivatives=False)
        e = self.p.weights.edges
        return np.concatenate(
            [
                (self.obs_weight[:, None] * state.error).ravel(),
                (np.sqrt(self.gamma[0]) * A @ self.R_s.T).ravel(),
                (self.edge_sqrt[:, None] * ((A[e[:, 0]] - A[e[:, 1]]) @ self.R_b.T)).ravel(),
                geo.rg,
            ]
        )

    def jacobian(self, theta: np.ndarray) -> sp.csr_array:
        """∂r/∂θ as CSR, assembled from vectorised COO blocks (same order as :meth:`residuals`)."""
        p, o = self.p, self.p.obs
        X, A, light = p.unpack(theta)
        geo = self.geometry(X, derivatives=True)
        st = self.render(X, A, light, geo.normals, derivatives=True)
        assert st.g is not None and st.h is not None and geo.dn is not None and geo.jg is not None
        n, nb, m = p.n_vertices, p.n_basis, o.count
        sx, sa, sl = p.slices()
        w = self.obs_weight
        jx = -st.colour[:, :, None] * st.g[:, None, :]
        if st.obs_grad is not None:
            jx = jx - st.obs_grad
        jx *= w[:, None, None]
        jn = w[:, None, None] * st.colour[:, :, None] * st.h[:, None, :]
        ja = (w * st.s)[:, None, None] * self.Q[o.illumination]
        gl = np.einsum("mab,ma->mb", self.light_maps[o.view], st.g)  # g̃ = M_cᵀ g
        jl = w[:, None, None] * st.colour[:, :, None] * gl[:, None, :]
        rows3 = 3 * np.arange(m)
        shape = (3 * m, p.size)
        ren = _blocks(rows3, 3 * o.vertex, jx, shape)
        ren = ren + _blocks(rows3, 3 * o.vertex, jn, (3 * m, 3 * n)) @ sp.hstack(
            [geo.dn.tocsr(), sp.csr_array((3 * n, p.size - 3 * n))]
        )
        ren = ren + _blocks(rows3, sa.start + nb * o.vertex, ja, shape)
        ren = ren + _blocks(rows3, sl.start + 3 * self.light_index, jl, shape)
        rs = np.broadcast_to(np.sqrt(self.gamma[0]) * self.R_s, (n, nb, nb))
        spec = _blocks(nb * np.arange(n), sa.start + nb * np.arange(n), rs, (nb * n, p.size))
        e = p.weights.edges
        blk = self.edge_sqrt[:, None, None] * self.R_b[None]
        rows_e = nb * np.arange(len(e))
        photo = _blocks(rows_e, sa.start + nb * e[:, 0], blk, (nb * len(e), p.size))
        photo = photo + _blocks(rows_e, sa.start + nb * e[:, 1], -blk, (nb * len(e), p.size))
        geom = sp.hstack([geo.jg, sp.csr_array((n, p.size - 3 * n))])
        return sp.vstack([ren, spec, photo, geom]).tocsr()

    # --- Gauss–Newton system -----------------------------------------------------------

    def linearise(self, theta: np.ndarray) -> Linearisation:
        """Terms, gradient Jᵀr and the pieces of JᵀJ at θ (robust weights frozen at θ).

        Per observation the rendering Jacobian over u = [δx, δn, δα] is
        ``A_o = w (c uᵀ + V)`` with ``u = [−g, h, 0]`` (shared by the frames of one view, as
        g and h depend only on the vertex, its normal and the view's light) and
        ``V = [−G, 0, s Q_k]``. Expanding ``A_oᵀA_o`` lets the sums run over (vertex, view)
        pairs and (vertex, illumination) groups instead of 14×14 products per observation.
        """
        p, o = self.p, self.p.obs
        X, A, light = p.unpack(theta)
        geo = self.geometry(X, derivatives=True)
        st = self.render(X, A, light, geo.normals, derivatives=True)
        assert st.g is not None and st.h is not None
        terms = self._terms(A, geo, st)
        _, rw = self._robust(st.error)
        wt = self.obs_weight * rw
        w2 = wt**2
        n, nb = p.n_vertices, p.n_basis
        n_ill = self.Q.shape[0]
        k = 6 + nb
        vs, ps = o.vertex_start, o.pair_start
        verts = o.vertex[vs]
        pair_vertex = o.vertex[ps]
        pvs = np.flatnonzero(np.r_[True, pair_vertex[1:] != pair_vertex[:-1]])
        col = st.colour
        r = wt[:, None] * st.error
        u6 = np.concatenate([-st.g[ps], st.h[ps]], axis=1)  # (P, 6)
        cq = np.empty((o.count, nb))
        for ill in range(n_ill):
            idx = o.illumination == ill
            cq[idx] = col[idx] @ self.Q[ill]
        e = np.zeros((o.count, k))
        e[:, 6:] = (w2 * st.s)[:, None] * cq
        if st.obs_grad is not None:
            e[:, :3] = -w2[:, None] * np.einsum("mc,mca->ma", col, st.obs_grad)
        e_p = _segment_sum(e, ps)
        cc_p = _segment_sum(w2 * np.einsum("mc,mc->m", col, col), ps)
        pair_e = _segment_sum(wt * np.einsum("mc,mc->m", col, r), ps)
        gram = np.zeros((n, k, k))
        gram[pair_vertex[pvs], :6, :6] = _segment_sum(
            cc_p[:, None, None] * u6[:, :, None] * u6[:, None, :], pvs
        )
        cross = _segment_sum(u6[:, :, None] * e_p[:, None, :], pvs)  # (V, 6, k)
        gram[pair_vertex[pvs], :6, :] += cross
        gram[pair_vertex[pvs], :, :6] += cross.transpose(0, 2, 1)
        grad_u = np.zeros((n, k))
        grad_u[pair_vertex[pvs], :6] = _segment_sum(u6 * pair_e[:, None], pvs)
        # V terms, grouped by (vertex, illumination) where they involve Q_k.
        key = o.vertex * n_ill + o.illumination
        size = n * n_ill
        ss = np.bincount(key, weights=w2 * st.s**2, minlength=size).reshape(n, n_ill)
        gram[:, 6:, 6:] += np.einsum("vk,kab->vab", ss, self.QtQ)
        sr = np.stack(
            [np.bincount(key, weights=wt * st.s * r[:, c], minlength=size) for c in range(3)],
            axis=1,
        ).reshape(n, n_ill, 3)
        grad_u[:, 6:] += np.einsum("vkc,kcb->vb", sr, self.Q)
        if st.obs_grad is not None:
            G = st.obs_grad
            gram[verts, :3, :3] += _segment_sum(
                w2[:, None, None] * np.einsum("mca,mcb->mab", G, G), vs
            )
            sg = np.stack(
                [
                    np.bincount(key, weights=w2 * st.s * G[:, c, a], minlength=size)
                    for c in range(3)
                    for a in range(3)
                ],
                axis=1,
            ).reshape(n, n_ill, 3, 3)  # Σ w² s G (c, a)
            xa = -np.einsum("vkca,kcb->vab", sg, self.Q)
            gram[:, :3, 6:] += xa
            gram[:, 6:, :3] += xa.transpose(0, 2, 1)
            grad_u[verts, :3] -= _segment_sum(wt[:, None] * np.einsum("mca,mc->ma", G, r), vs)
        pair_a = e_p.copy()
        pair_a[:, :6] += cc_p[:, None] * u6
        gl = np.einsum("pab,pa->pb", self.light_maps[o.view[ps]], st.g[ps])
        return Linearisation(
            cost=self,
            theta=theta,
            terms=terms,
            geometry=geo,
            A=A,
            gram=gram,
            grad_u=grad_u,
            pair_vertex=pair_vertex,
            pair_vertex_start=pvs,
            pair_light=self.light_index[ps],
            pair_a=pair_a,
            pair_g=gl,
            pair_e=pair_e,
            pair_cc=cc_p,
        )


def _blocks(
    row0: np.ndarray, col0: np.ndarray, blocks: np.ndarray, shape: tuple[int, int]
) -> sp.csr_array:
    """Sparse matrix with dense ``blocks`` (M, r, c) placed at (row0[m], col0[m])."""
    m, r, c = blocks.shape
    rows = (row0[:, None, None] + np.arange(r)[None, :, None]) + np.zeros((1, 1, c), dtype=np.int64)
    cols = (col0[:, None, None] + np.arange(c)[None, None, :]) + np.zeros((1, r, 1), dtype=np.int64)
    return sp.csr_array((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=shape)


@dataclass
class Linearisation:
    """JᵀJ and Jᵀr at one θ in factored form; products cost O(N + pairs), never forming J."""

    cost: JointCost
    theta: np.ndarray
    terms: dict[str, float]
    geometry: Geometry
    A: np.ndarray
    gram: np.ndarray  # per-vertex Σ A_oᵀA_o over u = [δx, δn, δα] (N, k, k)
    grad_u: np.ndarray  # (N, k)
    pair_vertex: np.ndarray  # (P,) sorted
    pair_vertex_start: np.ndarray  # first pair of each observed vertex
    pair_light: np.ndarray
    pair_a: np.ndarray  # Σ_o A_oᵀ(w c_o) per (vertex, view) pair (P, k)
    pair_g: np.ndarray  # light-parameter gradient of shading g̃ (P, 3)
    pair_e: np.ndarray  # Σ_o (w c_o)·r_o (P,)
    pair_cc: np.ndarray  # Σ_o |w c_o|² (P,)
    dn: sp.csr_array = field(init=False)
    dn_t: sp.csr_array = field(init=False)
    jg: sp.csr_array = field(init=False)
    jg_t: sp.csr_array = field(init=False)

    def __post_init__(self) -> None:
        assert self.geometry.dn is not None and self.geometry.jg is not None
        self.dn = self.geometry.dn.tocsr()
        self.dn_t = self.dn.T.tocsr()
        self.jg = self.geometry.jg
        self.jg_t = self.jg.T.tocsr()

    @property
    def n_light_blocks(self) -> int:
        return self.cost.p.n_light // 3

    def _pairs_to_vertices(self, values: np.ndarray) -> np.ndarray:
        out = np.zeros((self.cost.p.n_vertices, values.shape[1]))
        starts = self.pair_vertex_start
        out[self.pair_vertex[starts]] = _segment_sum(values, starts)
        return out

    def _pairs_to_lights(self, values: np.ndarray) -> np.ndarray:
        if self.n_light_blocks == 1:
            return values.sum(axis=0, keepdims=True)
        return np.stack(
            [np.bincount(self.pair_light, values[:, j], self.n_light_blocks) for j in range(3)],
            axis=1,
        )

    def _lift(self, dX: np.ndarray, dA: np.ndarray) -> np.ndarray:
        return np.concatenate([dX, (self.dn @ dX.ravel()).reshape(-1, 3), dA], axis=1)

    def _lower(self, yu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        gx = yu[:, :3] + (self.dn_t @ yu[:, 3:6].ravel()).reshape(-1, 3)
        return gx, yu[:, 6:]

    def gradient(self) -> np.ndarray:
        """Jᵀr (half the gradient of E)."""
        c = self.cost
        gx, ga = self._lower(self.grad_u)
        gx = gx + (self.jg_t @ self.geometry.rg).reshape(-1, 3)
        ga = ga + c.gamma[0] * self.A @ c.SS + (c.laplacian @ self.A) @ c.BB
        gl = self._pairs_to_lights(self.pair_g * self.pair_e[:, None])
        return c.p.pack(gx, ga, gl)

    def matvec(self, delta: np.ndarray) -> np.ndarray:
        """JᵀJ δ."""
        c = self.cost
        dX, dA, dL = c.p.unpack(delta)
        u = self._lift(dX, dA)
        yu = np.einsum("nij,nj->ni", self.gram, u)
        t = np.einsum("pj,pj->p", self.pair_g, dL[self.pair_light])
        yu += self._pairs_to_vertices(self.pair_a * t[:, None])
        q = np.einsum("pk,pk->p", self.pair_a, u[self.pair_vertex])
        yl = self._pairs_to_lights(self.pair_g * (q + self.pair_cc * t)[:, None])
        ox, oa = self._lower(yu)
        ox = ox + (self.jg_t @ (self.jg @ dX.ravel())).reshape(-1, 3)
        oa = oa + c.gamma[0] * dA @ c.SS + (c.laplacian @ dA) @ c.BB
        return c.p.pack(ox, oa, yl)

    def diagonal_blocks(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact diagonal blocks of JᵀJ: per vertex over [x (3), α (N_b)] and per light block
        (3×3) — the preconditioner and the Marquardt scaling."""
        c = self.cost
        dn = self.geometry.dn
        assert dn is not None
        n, nb = c.p.n_vertices, c.p.n_basis
        G = self.gram
        blk = np.zeros((n, 3 + nb, 3 + nb))
        blk[:, :3, :3] = G[:, :3, :3]
        blk[:, :3, 3:] = G[:, :3, 6:]
        blk[:, 3:, :3] = G[:, 6:, :3]
        blk[:, 3:, 3:] = G[:, 6:, 6:]
        # Normal chain: Σ_i D_ijᵀ G_nn(i) D_ij into column j, plus the i == j cross terms.
        rows = np.repeat(np.arange(n), np.diff(dn.indptr))
        cols = dn.indices
        D = dn.data
        contrib = np.einsum("bai,bac,bcj->bij", D, G[rows, 3:6, 3:6], D).reshape(-1, 9)
        xx = np.stack([np.bincount(cols, contrib[:, e], n) for e in range(9)], axis=1)
        xx = xx.reshape(n, 3, 3)
        self_blk = rows == cols
        ii = rows[self_blk]
        Dii = D[self_blk]
        cross = np.einsum("nab,nbc->nac", G[ii, :3, 3:6], Dii)
        xx[ii] += cross + cross.transpose(0, 2, 1)
        xa = np.einsum("nba,nbc->nac", Dii, G[ii, 3:6, 6:])
        blk[ii, :3, 3:] += xa
        blk[ii, 3:, :3] += xa.transpose(0, 2, 1)
        # Geometric smoothness: J_g in (1×3) blocks.
        jb = self.jg.tobsr(blocksize=(1, 3))
        v = jb.data[:, 0, :]
        outer = (v[:, :, None] * v[:, None, :]).reshape(-1, 9)
        xx += np.stack([np.bincount(jb.indices, outer[:, e], n) for e in range(9)], axis=1).reshape(
            n, 3, 3
        )
        blk[:, :3, :3] += xx
        blk[:, 3:, 3:] += c.gamma[0] * c.SS + c.lap_diag[:, None, None] * c.BB
        gg = self.pair_cc[:, None] * (self.pair_g[:, :, None] * self.pair_g[:, None, :]).reshape(
            -1, 9
        )
        light = self._pairs_to_lights_9(gg).reshape(-1, 3, 3)
        return blk, light

    def _pairs_to_lights_9(self, values: np.ndarray) -> np.ndarray:
        if self.n_light_blocks == 1:
            return values.sum(axis=0, keepdims=True)
        return np.stack(
            [np.bincount(self.pair_light, values[:, j], self.n_light_blocks) for j in range(9)],
            axis=1,
        )

    def light_coupling(self) -> np.ndarray | sp.csr_array:
        """Vertex-block × light block of JᵀJ for the preconditioner: dense (N, 3+N_b, 3) for
        the shared offset, sparse (N·(3+N_b), n_light) for free lights. Exact for α and for x
        through its own normal; a vertex's pull on its neighbours' normals is left out."""
        c = self.cost
        n, nb = c.p.n_vertices, c.p.n_basis
        bsr = self.geometry.dn
        assert bsr is not None
        d_self = np.zeros((n, 3, 3))
        rows = np.repeat(np.arange(n), np.diff(bsr.indptr))
        self_blk = rows == bsr.indices
        d_self[rows[self_blk]] = bsr.data[self_blk]
        a = self.pair_a
        v = self.pair_vertex
        b = np.concatenate(
            [a[:, :3] + np.einsum("pba,pb->pa", d_self[v], a[:, 3:6]), a[:, 6:]], axis=1
        )
        k = 3 + nb
        if self.n_light_blocks == 1:
            vals = (b[:, :, None] * self.pair_g[:, None, :]).reshape(-1, 3 * k)
            return self._pairs_to_vertices(vals).reshape(n, k, 3)
        vals = b[:, :, None] * self.pair_g[:, None, :]  # (P, k, 3)
        r = (v * k)[:, None, None] + np.arange(k)[None, :, None] + np.zeros((1, 1, 3), np.int64)
        col = (3 * self.pair_light)[:, None, None] + np.arange(3)[None, None, :]
        col = col + np.zeros((1, k, 1), dtype=np.int64)
        return sp.csr_array((vals.ravel(), (r.ravel(), col.ravel())), shape=(n * k, c.p.n_light))
