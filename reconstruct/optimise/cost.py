"""The joint cost of the paper, eq. (1), as residuals, an exact sparse Jacobian, and the
Gauss–Newton system the solver uses.

Residual blocks (E = Σ r², the paper's cost with no ½):

* rendering (eq. 2, 12): per observation o = (vertex i, frame f), 3 channels,
  ``r_o = k (y(x_i, α_i, p_c) − y_obs(π_c(x_i))) / sqrt(|V(i)|)``; y from
  :mod:`reconstruct.model.forward`,
  y_obs sampled bilinearly at the vertex's projection (disparity cue),
  k the rendering unit (``Weights.rendering_scale``) times the frame's noise weight
  (``Frames.weight``, below 1 where an ambient frame was subtracted) and its own factor
  (``Weights.observation``, below 1 on highlights);
* spectral regulariser: ``sqrt(γ1) R_s α_i`` with ``R_sᵀR_s`` the matrix of
  ``Weights.spectral`` (:mod:`calibration.prior`: the training prior, or the paper's spectral
  smoothness, eq. 14, ``R_sᵀR_s = (D B)ᵀ(D B)``, when none is given);
* photometric smoothness (eq. 15): ``sqrt(2 γ2 w_ij) R_b (α_i − α_j)`` per undirected edge with
  ``R_bᵀR_b = PᵀBᵀBP`` (the paper's double sum visits each edge twice), P the projection onto
  what the rig's responses see (:func:`seen_projection`): in the rest, which no observation
  holds, neighbours would pass their spectra across the whole mesh (a black patch took the far
  red of the paints around it), and the spectral regulariser completes each vertex alone;
* geometric smoothness (eq. 16): ``sqrt(γ3) n_iᵀ(x_i − x̄_i) / l_i``: distance of the vertex to the
  plane through its neighbours' centroid x̄_i with the vertex normal, over the scale l_i.

The R factors (QR of D B and B) give identical costs with N_b rows instead of N_λ. A robust loss
(Huber/Cauchy on an observation's RGB error) is applied by iteratively reweighting the rendering
residuals; :meth:`JointCost.residuals`/:meth:`jacobian` expose the plain least-squares cost so a
benchmark can hand it to ``scipy.optimize.least_squares``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp

from calibration.prior import SpectralRegulariser, smoothness_gram
from reconstruct.model.forward import render_values, shading
from reconstruct.optimise.kernels.normal_equations import (
    accumulate_normal_equations,
)
from reconstruct.optimise.kernels.rendering import rendered_error, shading_gradients
from reconstruct.optimise.kernels.sampling import project_points
from reconstruct.optimise.linearisation import Linearisation
from reconstruct.optimise.mesh import NormalJacobian, adjacency, ring_mean, vertex_normals
from reconstruct.optimise.problem import Problem
from reconstruct.optimise.sampling import sample_pairs, view_cameras

Robust = Literal["none", "huber", "cauchy"]
TERMS = ("rendering", "spectral", "photometric", "geometric")


def _r_factor(m: np.ndarray) -> np.ndarray:
    """Square R with ``RᵀR = mᵀm`` (QR of a tall matrix)."""
    return np.asarray(np.linalg.qr(m, mode="r"))


def seen_projection(B: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The projection P (N_b, N_b) of basis weights onto the part the responses ``Q``
    (K, 3, N_b) see, along their null space, orthogonal in the spectra's metric BᵀB: two
    weights with the same responses have the same P α, and P α is the smallest spectrum that
    renders as α does.

    >>> B = np.eye(3); Q = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]])
    >>> np.allclose(seen_projection(B, Q) @ [1.0, 2.0, 3.0], [1.0, 2.0, 0.0])
    True
    """
    metric_inv = np.linalg.pinv(B.T @ B, hermitian=True)
    rows = Q.reshape(-1, Q.shape[-1])
    return metric_inv @ rows.T @ np.linalg.pinv(rows @ metric_inv @ rows.T, hermitian=True) @ rows


def _summation(index: np.ndarray, n_rows: int) -> sp.csr_array:
    """(n_rows × M) 0/1 matrix summing the rows of an (M, c) array into groups ``index``: a
    sparse product runs these segment sums in one compiled loop over all columns."""
    m = index.size
    return sp.csr_array(
        (np.ones(m), (np.asarray(index, dtype=np.int64), np.arange(m))), shape=(n_rows, m)
    )


@dataclass
class RenderState:
    """Per-observation quantities at one θ; the geometric ones are per (vertex, view) pair
    (shared by that view's frames), derivative parts only when asked."""

    colours: np.ndarray  # unit-shading rendered RGB C^T L_k B α_i per (k, i) (K, N, 3)
    error: np.ndarray  # y − y_obs (M, 3)
    pair_s: np.ndarray  # shading per pair (P,)
    g: np.ndarray | None = None  # ∂s/∂p (= −∂s/∂x with n fixed) per pair (P, 3)
    h: np.ndarray | None = None  # ∂s/∂n per pair (P, 3)
    # ∂y_obs/∂x = image_grad (M, 3, 2) @ proj_jac (P, 2, 3) of the observation's pair;
    # None for fixed observations.
    image_grad: np.ndarray | None = None
    proj_jac: np.ndarray | None = None

    def obs_grad(self, obs_pair: np.ndarray) -> np.ndarray | None:
        """∂y_obs/∂x per observation (M, 3, 3)."""
        if self.image_grad is None or self.proj_jac is None:
            return None
        return self.image_grad @ self.proj_jac[obs_pair]


@dataclass
class Geometry:
    normals: np.ndarray
    dn: sp.bsr_array | None
    jg: sp.csr_array | None
    rg: np.ndarray  # geometric residuals (N,)
    jg_blocks: np.ndarray | None = None  # ∂rg_i/∂x_j per block of dn's sparsity (blocks, 3)


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
        spectral = p.weights.spectral or SpectralRegulariser("smoothness", smoothness_gram(B))
        self.R_s = spectral.factor
        self.R_b = _r_factor(B @ seen_projection(B, self.Q))
        self.SS = self.R_s.T @ self.R_s
        self.BB = self.R_b.T @ self.R_b
        self.QtQ = np.einsum("kcb,kcd->kbd", self.Q, self.Q)
        g1, g2, g3 = p.weights.gamma
        self.gamma = (float(g1), float(g2), float(g3))
        n = p.n_vertices
        self.ring_mean = ring_mean(adjacency(p.faces, n))
        self.normal_jacobian = NormalJacobian(p.faces, n)
        nj = self.normal_jacobian
        # I − ring mean on dn's block sparsity (same 1-ring, plus the diagonal).
        self.umbrella_blocks = (nj.block_row == nj.block_col) - np.asarray(
            self.ring_mean[nj.block_row, nj.block_col]
        ).ravel()
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
        if p.frames.weight is not None:  # noisier (ambient-subtracted) frames count less
            self.obs_weight = self.obs_weight * np.asarray(p.frames.weight, dtype=float)[o.frame]
        if p.weights.observation is not None:  # highlights count less
            self.obs_weight = self.obs_weight * p.weights.observation
        self.light_maps = p.light_maps()  # ∂p_c/∂θ_light (N_views, 3, 3)
        # (vertex, view) pairs: the geometry of one pair is shared by that view's frames.
        ps = o.pair_start
        self.obs_pair = np.repeat(np.arange(ps.size, dtype=np.int32), np.diff(np.r_[ps, o.count]))
        self.pair_vertex = o.vertex[ps]
        self.pair_view = o.view[ps]
        # which light each pair sees: the shared offset (0), or its view's own light
        self.pair_light = np.zeros(ps.size, np.int64) if p.light_mode == "offset" else o.view[ps]
        self.view_pairs = [np.flatnonzero(self.pair_view == c) for c in range(p.rig.n_views)]
        self.n_illuminations = self.Q.shape[0]
        self.pair_to_light = _summation(self.pair_light, p.n_light // 3)
        self.vertex_pairs = np.searchsorted(self.pair_vertex, np.arange(n + 1))
        self.pair_obs = np.r_[ps, o.count]
        self.cameras = view_cameras(p.rig.intrinsics, p.rig.poses)
        # (θ, positions, geometry, render, terms) of the last `terms` call, for `linearise`
        self._evaluated: tuple[np.ndarray, bool, Geometry, RenderState, dict[str, float]] | None = (
            None
        )
        self._sampled: tuple[np.ndarray, np.ndarray] | None = None  # (X, y_obs), positions fixed

    # --- evaluation ---------------------------------------------------------------------

    def geometry(self, X: np.ndarray, derivatives: bool) -> Geometry:
        p = self.p
        normals, length = vertex_normals(X, p.faces)
        offset = X - self.ring_mean @ X
        k = np.sqrt(self.gamma[2]) / p.weights.scale
        rg = k * np.einsum("ij,ij->i", normals, offset)
        if not derivatives:
            return Geometry(normals, None, None, rg)
        dn = self.normal_jacobian(X, (normals, length))
        nj = self.normal_jacobian
        # ∂rg_i/∂x_j = k_i ((δ_ij − R_ij) n_iᵀ + offset_iᵀ ∂n_i/∂x_j), on dn's blocks.
        i = nj.block_row
        blocks = self.umbrella_blocks[:, None] * normals[i] + np.einsum(
            "ba,bac->bc", offset[i], dn.data
        )
        blocks *= k[i, None]
        n = p.n_vertices
        jg = sp.csr_array(
            (blocks.ravel(), (3 * nj.block_col[:, None] + np.arange(3)).ravel(), 3 * nj.indptr),
            shape=(n, 3 * n),
        )
        return Geometry(normals, dn, jg, rg, blocks)

    def render(
        self,
        X: np.ndarray,
        A: np.ndarray,
        light: np.ndarray,
        normals: np.ndarray,
        derivatives: bool,
        positions: bool = True,
    ) -> RenderState:
        """Rendered vs observed RGB for every observation (the forward model of forward.py).

        ``positions=False`` leaves out the derivatives with respect to the vertex positions
        that only the observed side has (image gradients, projection Jacobians)."""
        p, o = self.p, self.p.obs
        P = p.light_positions(light)
        pv = self.pair_vertex
        s_pair = shading(X[pv], normals[pv], P[self.pair_view])
        refl = A @ self.B.T
        unit = np.ones(p.n_vertices)
        colours = np.stack([render_values(refl, unit, resp) for resp in p.rig.responses])
        if o.fixed_rgb is not None:
            y_obs, image_grad, duv = o.fixed_rgb, None, None
        else:
            y_obs, image_grad, duv = self._sample(X, derivatives and positions)
        if p.weights.observed_offset is not None:
            y_obs = y_obs - p.weights.observed_offset
        error = rendered_error(colours, s_pair, self.obs_pair, o.vertex, o.illumination, y_obs)
        state = RenderState(colours, error, s_pair, image_grad=image_grad, proj_jac=duv)
        if derivatives:
            state.g, state.h = shading_gradients(
                np.ascontiguousarray(X), normals, P, pv, self.pair_view, s_pair
            )
        return state

    def _sample(
        self, X: np.ndarray, gradient: bool
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Observed RGB at the vertices' projections (M, 3), with ``gradient`` the image
        gradients (M, 3, 2) and projection Jacobians per pair (P, 2, 3). Samples without
        gradients are kept: while the positions stay (the light-only stage) they are the same.
        With gradients the positions are moving, and the linearisation at the same X reuses
        its evaluation's whole state instead."""
        kept = self._sampled
        if not gradient and kept is not None and np.array_equal(kept[0], X):
            return kept[1], None, None
        kept = self._sampled = None  # free the old samples before the new ones exist
        p, o = self.p, self.p.obs
        images = p.frames.images
        assert images is not None
        uv, jac = project_points(X, self.pair_vertex, self.pair_view, *self.cameras, gradient)
        y_obs, grad = sample_pairs(images, o.frame, self.obs_pair, uv, gradient)
        if gradient:
            return y_obs, grad, jac
        self._sampled = (np.array(X, copy=True), y_obs)
        return y_obs, None, None

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

    def terms(self, theta: np.ndarray, positions: bool = True) -> dict[str, float]:
        """Each term of eq. (1) (already multiplied by its γ) and the total.

        The render's derivative parts are evaluated too and kept for a :meth:`linearise` at the
        same θ: the solver evaluates every trial step and linearises where it accepts one, so
        the render (projections, image samples) is shared instead of repeated. ``positions``:
        whether that linearisation will need the vertex-position derivatives."""
        geo, state, _ = self._evaluate(theta, positions, reuse=False)
        terms = self._terms(self.p.unpack(theta)[1], geo, state)
        self._evaluated = (np.array(theta, copy=True), positions, geo, state, terms)
        return terms

    def _evaluate(
        self, theta: np.ndarray, positions: bool, reuse: bool = True
    ) -> tuple[Geometry, RenderState, dict[str, float] | None]:
        """Geometry and render with derivatives at θ, and the terms there (from :meth:`terms`
        when it was there, else None).

        :meth:`terms` (``reuse=False``) leaves the normal Jacobian out: a trial step needs only
        the cost, and the linearisation after an accepted one adds it here (a rejected or
        shortened trial never pays for it)."""
        kept, self._evaluated = self._evaluated, None
        terms = None
        if reuse and kept is not None and kept[1] == positions and np.array_equal(kept[0], theta):
            geo, state, terms = kept[2], kept[3], kept[4]
        else:
            kept = None  # free the kept state before a new one exists (it scales with observations)
            X, A, light = self.p.unpack(theta)
            geo = self.geometry(X, derivatives=positions and reuse)
            state = self.render(X, A, light, geo.normals, derivatives=True, positions=positions)
        if reuse and positions and geo.dn is None:
            geo = self.geometry(self.p.unpack(theta)[0], derivatives=True)  # same terms
        return geo, state, terms

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
        g, h = st.g[self.obs_pair], st.h[self.obs_pair]
        colour = st.colours[o.illumination, o.vertex]
        jx = -colour[:, :, None] * g[:, None, :]
        obs_grad = st.obs_grad(self.obs_pair)
        if obs_grad is not None:
            jx = jx - obs_grad
        jx *= w[:, None, None]
        jn = w[:, None, None] * colour[:, :, None] * h[:, None, :]
        ja = (w * st.pair_s[self.obs_pair])[:, None, None] * self.Q[o.illumination]
        gl = np.einsum("mab,ma->mb", self.light_maps[o.view], g)  # g̃ = M_cᵀ g
        jl = w[:, None, None] * colour[:, :, None] * gl[:, None, :]
        rows3 = 3 * np.arange(m)
        shape = (3 * m, p.size)
        ren = _blocks(rows3, 3 * o.vertex, jx, shape)
        ren = ren + _blocks(rows3, 3 * o.vertex, jn, (3 * m, 3 * n)) @ sp.hstack(
            [geo.dn.tocsr(), sp.csr_array((3 * n, p.size - 3 * n))]
        )
        ren = ren + _blocks(rows3, sa.start + nb * o.vertex, ja, shape)
        light = self.pair_light[self.obs_pair]
        ren = ren + _blocks(rows3, sl.start + 3 * light, jl, shape)
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

    def linearise(self, theta: np.ndarray, positions: bool = True) -> Linearisation:
        """Terms, gradient Jᵀr and the pieces of JᵀJ at θ (robust weights frozen at θ).

        ``positions=False`` (a stage with the vertices fixed) leaves out what only the
        position parameters need — the normal Jacobian, the geometric term's Jacobian, the
        image gradients: the α and light parts stay exact, the position parts are not
        meaningful and must stay masked.

        Per observation o of pair p = (vertex i, view c) the rendering Jacobian over
        u = [δx, δn, δα] is ``A_o = w (c_o u_pᵀ + V_o)`` with ``u_p = [−g, h, 0]`` (shared by the
        frames of one view: g and h depend only on the vertex, its normal and the view's light)
        and ``V_o = [−G_o, 0, s Q_k]``. Expanding ``A_oᵀA_o`` lets the sums run over pairs and
        (vertex, illumination) groups instead of k×k products per observation; one compiled
        pass over the observations accumulates them
        (:mod:`reconstruct.optimise.kernels.normal_equations`). The light enters through
        ``w c_o g̃_pᵀ`` (g̃ = M_cᵀ g),
        so its coupling to vertex i is ``C_i = Σ_p a_p g̃_pᵀ`` with ``a_p = Σ_o A_oᵀ w c_o``.
        """
        p, o = self.p, self.p.obs
        A = p.unpack(theta)[1]
        geo, st, terms = self._evaluate(theta, positions)
        assert st.g is not None and st.h is not None
        if terms is None:
            terms = self._terms(A, geo, st)
        wt = self.obs_weight
        if self.robust != "none":  # the IRLS weights (1 without a robust loss)
            wt = wt * self._robust(st.error)[1]
        gl = np.empty_like(st.g)  # g̃ = M_cᵀ g per pair
        for c, idx in enumerate(self.view_pairs):
            gl[idx] = st.g[idx] @ self.light_maps[c]
        grad, duv = st.image_grad, st.proj_jac
        if grad is None or duv is None:  # fixed observations or fixed positions
            grad, duv = np.empty((0, 3, 2)), np.empty((0, 2, 3))
        shared = p.n_light == 3
        gram, shading2, grad_u, a, cc, pair_e, coupling = accumulate_normal_equations(
            self.vertex_pairs,
            self.pair_obs,
            o.illumination,
            wt,
            st.colours,
            wt[:, None] * st.error,
            grad,
            st.pair_s,
            st.g,
            st.h,
            duv,
            gl,
            self.Q,
            shared,
        )
        # Σ_p cc_p g̃_p g̃_pᵀ per light: one (3 × P)(P × 3) product for the shared light, else a
        # row at a time (no (pairs × 9) temporaries)
        if shared:
            light_block = ((cc[:, None] * gl).T @ gl)[None]
        else:
            light_block = np.stack(
                [self.pair_to_light @ ((cc * gl[:, r])[:, None] * gl) for r in range(3)], axis=1
            )
        light_grad = self.pair_to_light @ (gl * pair_e[:, None])
        if not shared:
            coupling = _pair_coupling(
                self.pair_vertex, self.pair_light, a, gl, p.n_vertices, p.n_light
            )
        if positions:  # the positions move next: their samples and image gradients are spent
            self._sampled = None
        return Linearisation(
            cost=self,
            theta=theta,
            terms=terms,
            geometry=geo,
            A=A,
            gram=gram,
            shading2=shading2,
            grad_u=grad_u,
            coupling=coupling,
            light_block=light_block,
            light_grad=light_grad,
        )


def _pair_coupling(
    pair_vertex: np.ndarray,
    pair_light: np.ndarray,
    a: np.ndarray,
    gl: np.ndarray,
    n_vertices: int,
    n_light: int,
) -> sp.csr_array:
    """Free lights: the (N·k × n_light) coupling with one k×3 block ``a_p g̃_pᵀ`` per pair
    (each pair is one (vertex, light), so no two blocks overlap)."""
    k = a.shape[1]
    rows = (k * pair_vertex)[:, None, None] + np.arange(k)[None, :, None]
    cols = (3 * pair_light)[:, None, None] + np.arange(3)[None, None, :]
    rows, cols = np.broadcast_arrays(rows, cols)
    vals = a[:, :, None] * gl[:, None, :]
    return sp.csr_array(
        (vals.ravel(), (rows.ravel(), cols.ravel())), shape=(n_vertices * k, n_light)
    )


def _blocks(
    row0: np.ndarray, col0: np.ndarray, blocks: np.ndarray, shape: tuple[int, int]
) -> sp.csr_array:
    """Sparse matrix with dense ``blocks`` (M, r, c) placed at (row0[m], col0[m])."""
    m, r, c = blocks.shape
    rows = (row0[:, None, None] + np.arange(r)[None, :, None]) + np.zeros((1, 1, c), dtype=np.int64)
    cols = (col0[:, None, None] + np.arange(c)[None, None, :]) + np.zeros((1, r, 1), dtype=np.int64)
    return sp.csr_array((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=shape)
