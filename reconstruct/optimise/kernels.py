"""Compiled loops of the joint cost and its solver: bilinear image samples, the Gauss–Newton
accumulation of :meth:`~reconstruct.optimise.cost.JointCost.linearise`, the normals and
their Jacobian, the products with JᵀJ and its preconditioners, and CG's vector updates.

The first two walk millions of observations. In NumPy each intermediate quantity was a separate
(observations × ·) array, written and read back once per pass (at 100k vertices ~2M
observations, a dozen passes per linearisation); here one loop per vertex reads each
observation once and keeps its sums in registers, and the vertices run in parallel. The
observations are sorted by (vertex, view, frame) (``problem.Observations``), so a vertex's
pairs and a pair's frames are contiguous ranges.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange, types
from numba.extending import overload

# float16 as float64, by bit pattern: numba has no float16 type on the CPU, so float16 frames
# reach the kernels as their uint16 bits and are decoded by this table (exact, 0.5 MB).
HALF_TABLE = np.arange(2**16, dtype=np.uint16).view(np.float16).astype(np.float64)
_NO_TABLE = np.empty(0)


def texel(texels: np.ndarray, table: np.ndarray, f: int, r: int, c: int, ch: int) -> float:
    """One image value as float64: ``texels`` are floats, or float16 bits decoded by ``table``."""
    raise NotImplementedError("compiled only (numba overload below)")


@overload(texel, inline="always")
def _texel(texels, table, f, r, c, ch):
    if isinstance(texels.dtype, types.Integer):
        return lambda texels, table, f, r, c, ch: table[texels[f, r, c, ch]]
    return lambda texels, table, f, r, c, ch: float(texels[f, r, c, ch])


def sample_bilinear(
    images: np.ndarray,
    frame: np.ndarray,
    obs_pair: np.ndarray,
    index: np.ndarray,
    frac: np.ndarray,
    gradient: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear values (M, C) of ``images`` (F, H, W, C) and with ``gradient`` their
    ``∂value/∂(u, v)`` (M, C, 2) (else an empty array). Observation m reads frame
    ``frame[m]`` at the taps of its pair ``obs_pair[m]``: the flat top-left tap ``index`` (P,)
    and the fractions ``frac`` (P, 2) along columns and rows (``sampling.bilinear_taps``).
    float16 images are read through :data:`HALF_TABLE`."""
    half = images.dtype == np.float16
    texels, table = (images.view(np.uint16), HALF_TABLE) if half else (images, _NO_TABLE)
    return _sample_bilinear(texels, table, frame, obs_pair, index, frac, gradient)


@njit(parallel=True, cache=True, fastmath=True)
def _sample_bilinear(
    texels: np.ndarray,
    table: np.ndarray,
    frame: np.ndarray,
    obs_pair: np.ndarray,
    index: np.ndarray,
    frac: np.ndarray,
    gradient: bool,
) -> tuple[np.ndarray, np.ndarray]:
    m_count = obs_pair.size
    width, nc = texels.shape[2], texels.shape[3]
    value = np.empty((m_count, nc))
    grad = np.empty((m_count if gradient else 0, nc, 2))
    for m in prange(m_count):
        p = obs_pair[m]
        r0, c0 = divmod(index[p], width)
        fc, fr = frac[p, 0], frac[p, 1]
        f = frame[m]
        for c in range(nc):
            i00 = texel(texels, table, f, r0, c0, c)
            i01 = texel(texels, table, f, r0, c0 + 1, c)
            i10 = texel(texels, table, f, r0 + 1, c0, c)
            i11 = texel(texels, table, f, r0 + 1, c0 + 1, c)
            d0 = i01 - i00
            d1 = i11 - i10
            top = i00 + fc * d0
            dv = i10 + fc * d1 - top
            value[m, c] = top + fr * dv
            if gradient:
                grad[m, c, 0] = d0 + fr * (d1 - d0)
                grad[m, c, 1] = dv
    return value, grad


@njit(parallel=True, cache=True, fastmath=True)
def accumulate_normal_equations(
    vertex_pairs: np.ndarray,
    pair_obs: np.ndarray,
    illumination: np.ndarray,
    weight: np.ndarray,
    colours: np.ndarray,
    residual: np.ndarray,
    image_grad: np.ndarray,
    pair_shading: np.ndarray,
    g: np.ndarray,
    h: np.ndarray,
    proj_jac: np.ndarray,
    light_grad: np.ndarray,
    Q: np.ndarray,
    shared_light: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per-vertex blocks of JᵀJ and Jᵀr over u = [δx, δn, δα] (k = 6 + N_b).

    Per observation o of pair p (vertex i, view c) the rendering Jacobian row block is
    ``A_o = w (c_o u_pᵀ + V_o)``, ``u_p = [−g, h, 0]``, ``V_o = [−G_o, 0, s Q_k]`` with
    ``G_o = grad_o duv_p`` (see ``JointCost.linearise``); ``r_o = w e_o``. Inputs: pairs of
    vertex i are ``vertex_pairs[i]:vertex_pairs[i+1]``, observations of pair p
    ``pair_obs[p]:pair_obs[p+1]``; ``weight`` w (M,), ``colours`` c per (illumination,
    vertex) (K, N, 3), ``residual`` r = w e (M, 3), ``image_grad`` (M, 3, 2) or empty (fixed
    observations), per pair the shading s, g, h (P, 3), ``proj_jac`` (P, 2, 3) and
    ``light_grad`` g̃ = M_cᵀ g (P, 3); ``Q`` (K, 3, N_b).

    Returns the gram Σ_o A_oᵀA_o by its position rows (N, 6, k) — its α×α block is
    ``Σ_k s2_k QᵀQ_k`` with the returned per-(vertex, illumination) weights s2 = Σ w² s²
    (N, K), stored as those K numbers instead of N_b² (68 instead of 157 MB at 100k) —
    grad_u (N, k), a_p = Σ_o A_oᵀ w c_o (P, k; empty for a light
    shared by all views), cc_p = Σ_o |w c_o|² (P,), e_p = Σ_o w c_o·r_o (P,) and, for a shared
    light, the vertex–light coupling Σ_p a_p g̃_pᵀ (N, k, 3) (else empty).
    """
    n = vertex_pairs.size - 1
    n_pairs = pair_obs.size - 1
    n_ill, _, nb = Q.shape
    k = 6 + nb
    images = image_grad.shape[0] > 0
    gram = np.zeros((n, 6, k))
    shading2 = np.zeros((n, n_ill))
    grad_u = np.zeros((n, k))
    a_all = np.zeros((0 if shared_light else n_pairs, k))  # only free lights need a_p
    cc_all = np.zeros(n_pairs)
    e_all = np.zeros(n_pairs)
    coupling = np.zeros((n if shared_light else 0, k, 3))
    for i in prange(n):
        group_s2 = shading2[i]  # Σ w² s² per illumination
        group_sr = np.zeros((n_ill, 3))  # Σ w s r per illumination
        u = np.zeros(6)
        a = np.zeros(k)
        e_alpha = np.zeros(nb)
        pg = np.zeros((2, nb))
        for p in range(vertex_pairs[i], vertex_pairs[i + 1]):
            cc = 0.0
            pe = 0.0
            e_alpha[:] = 0.0
            gtg00 = gtg01 = gtg11 = 0.0
            gc0 = gc1 = gr0 = gr1 = 0.0
            pg[:] = 0.0
            for o in range(pair_obs[p], pair_obs[p + 1]):
                w = weight[o]
                w2 = w * w
                ill = illumination[o]
                c0, c1, c2 = colours[ill, i, 0], colours[ill, i, 1], colours[ill, i, 2]
                r0, r1, r2 = residual[o, 0], residual[o, 1], residual[o, 2]
                cc += w2 * (c0 * c0 + c1 * c1 + c2 * c2)
                pe += w * (c0 * r0 + c1 * r1 + c2 * r2)
                for b in range(nb):
                    e_alpha[b] += w2 * (c0 * Q[ill, 0, b] + c1 * Q[ill, 1, b] + c2 * Q[ill, 2, b])
                s = pair_shading[p]
                group_s2[ill] += w2 * s * s
                group_sr[ill, 0] += w * s * r0
                group_sr[ill, 1] += w * s * r1
                group_sr[ill, 2] += w * s * r2
                if images:
                    x0, x1, x2 = image_grad[o, 0, 0], image_grad[o, 1, 0], image_grad[o, 2, 0]
                    y0, y1, y2 = image_grad[o, 0, 1], image_grad[o, 1, 1], image_grad[o, 2, 1]
                    gtg00 += w2 * (x0 * x0 + x1 * x1 + x2 * x2)
                    gtg01 += w2 * (x0 * y0 + x1 * y1 + x2 * y2)
                    gtg11 += w2 * (y0 * y0 + y1 * y1 + y2 * y2)
                    gc0 += w2 * (x0 * c0 + x1 * c1 + x2 * c2)
                    gc1 += w2 * (y0 * c0 + y1 * c1 + y2 * c2)
                    gr0 += w * (x0 * r0 + x1 * r1 + x2 * r2)
                    gr1 += w * (y0 * r0 + y1 * r1 + y2 * r2)
                    ws = w2 * s
                    for b in range(nb):
                        q0, q1, q2 = Q[ill, 0, b], Q[ill, 1, b], Q[ill, 2, b]
                        pg[0, b] += ws * (x0 * q0 + x1 * q1 + x2 * q2)
                        pg[1, b] += ws * (y0 * q0 + y1 * q1 + y2 * q2)
            for d in range(3):
                u[d] = -g[p, d]
                u[3 + d] = h[p, d]
            # a_p = cc u_p + Σ_o w² V_oᵀ c_o
            for d in range(6):
                a[d] = cc * u[d]
            for b in range(nb):
                a[6 + b] = pair_shading[p] * e_alpha[b]
            if images:
                for d in range(3):
                    a[d] -= proj_jac[p, 0, d] * gc0 + proj_jac[p, 1, d] * gc1
            # Σ_o A_oᵀA_o = u aᵀ + a uᵀ − cc u uᵀ + Σ_o w² V_oᵀV_o (the last below), rows < 6
            for r in range(6):
                for q in range(k):
                    gram[i, r, q] += u[r] * a[q]
                for q in range(6):
                    gram[i, r, q] += a[r] * u[q] - cc * u[r] * u[q]
                grad_u[i, r] += u[r] * pe
            if images:
                # duvᵀ (Σ w² gradᵀgrad) duv, −duvᵀ Σ w gradᵀr, −duvᵀ Σ w² s gradᵀQ
                for r in range(3):
                    jr0, jr1 = proj_jac[p, 0, r], proj_jac[p, 1, r]
                    t0 = gtg00 * jr0 + gtg01 * jr1
                    t1 = gtg01 * jr0 + gtg11 * jr1
                    for q in range(3):
                        gram[i, r, q] += t0 * proj_jac[p, 0, q] + t1 * proj_jac[p, 1, q]
                    grad_u[i, r] -= jr0 * gr0 + jr1 * gr1
                    for b in range(nb):
                        xa = jr0 * pg[0, b] + jr1 * pg[1, b]
                        gram[i, r, 6 + b] -= xa
            if not shared_light:
                for q in range(k):
                    a_all[p, q] = a[q]
            cc_all[p] = cc
            e_all[p] = pe
            if shared_light:
                for q in range(k):
                    for d in range(3):
                        coupling[i, q, d] += a[q] * light_grad[p, d]
        for ill in range(n_ill):
            for b in range(nb):
                grad_u[i, 6 + b] += (
                    group_sr[ill, 0] * Q[ill, 0, b]
                    + group_sr[ill, 1] * Q[ill, 1, b]
                    + group_sr[ill, 2] * Q[ill, 2, b]
                )
    return gram, shading2, grad_u, a_all, cc_all, e_all, coupling


@njit(parallel=True, cache=True, fastmath=True)
def gram_products(
    gram: np.ndarray,
    shading2: np.ndarray,
    Q: np.ndarray,
    dX: np.ndarray,
    dA: np.ndarray,
    dn_indptr: np.ndarray,
    dn_col: np.ndarray,
    dn_blocks: np.ndarray,
    jg_blocks: np.ndarray,
    coupling: np.ndarray,
    dL: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """First half of ``Linearisation.matvec``: per vertex the lifted step
    u = [δx, δn = Σ_j D_ij δx_j, δα] (N, k) and ``G u (+ C_i δl)`` (N, k), with the gram G by
    its position rows ``gram`` (N, 6, k) and its α×α block ``Σ_k shading2[i, k] Q_kᵀQ_k``
    (:func:`accumulate_normal_equations`; applied as ``Q_kᵀ (Q_k δα)``, ``Q`` (K, 3, N_b): 6 N_b
    products per illumination instead of N_b²). ``dn_*`` is the block-CSR normal Jacobian
    (empty ``dn_blocks``: positions fixed, δn = 0); ``coupling`` (N, k, 3) with the shared
    light's step ``dL`` (3,), or empty.

    Also returns, summed in the same pass instead of re-reading C, u and the blocks: the shared
    light's rows ``Σ_i C_iᵀ u_i`` (3,; zeros without a coupling) and the geometric term's
    ``J_g δx`` (N,) from its blocks ``jg_blocks`` (blocks, 3) on the normal Jacobian's
    sparsity (empty: none)."""
    n, k = gram.shape[0], gram.shape[2]
    nb = dA.shape[1]
    n_ill = Q.shape[0]
    with_normals = dn_blocks.shape[0] > 0
    with_geometric = jg_blocks.shape[0] > 0
    shared = coupling.shape[0] > 0
    u = np.empty((n, k))
    yu = np.empty((n, k))
    jdx = np.empty(n if with_geometric else 0)
    l0 = 0.0
    l1 = 0.0
    l2 = 0.0
    for i in prange(n):
        n0 = 0.0
        n1 = 0.0
        n2 = 0.0
        jd = 0.0
        if with_normals:
            for b in range(dn_indptr[i], dn_indptr[i + 1]):
                j = dn_col[b]
                x0, x1, x2 = dX[j, 0], dX[j, 1], dX[j, 2]
                n0 += dn_blocks[b, 0, 0] * x0 + dn_blocks[b, 0, 1] * x1 + dn_blocks[b, 0, 2] * x2
                n1 += dn_blocks[b, 1, 0] * x0 + dn_blocks[b, 1, 1] * x1 + dn_blocks[b, 1, 2] * x2
                n2 += dn_blocks[b, 2, 0] * x0 + dn_blocks[b, 2, 1] * x1 + dn_blocks[b, 2, 2] * x2
                if with_geometric:
                    jd += jg_blocks[b, 0] * x0 + jg_blocks[b, 1] * x1 + jg_blocks[b, 2] * x2
        if with_geometric:
            jdx[i] = jd
        ui = u[i]
        ui[0], ui[1], ui[2] = dX[i, 0], dX[i, 1], dX[i, 2]
        ui[3], ui[4], ui[5] = n0, n1, n2
        for b in range(nb):
            ui[6 + b] = dA[i, b]
        y = yu[i]
        for r in range(k):
            y[r] = 0.0
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        if shared:
            c = coupling[i]
            for r in range(k):
                y[r] = c[r, 0] * dL[0] + c[r, 1] * dL[1] + c[r, 2] * dL[2]
                a0 += c[r, 0] * ui[r]
                a1 += c[r, 1] * ui[r]
                a2 += c[r, 2] * ui[r]
        l0 += a0  # prange reductions: at the loop body's top level only
        l1 += a1
        l2 += a2
        for r in range(6):  # the position rows, and their transposes into the α rows
            acc = 0.0
            for q in range(k):
                acc += gram[i, r, q] * ui[q]
            y[r] += acc
            ur = ui[r]
            for b in range(nb):
                y[6 + b] += gram[i, r, 6 + b] * ur
        for ill in range(n_ill):  # α×α: s Qᵀ (Q δα)
            s = shading2[i, ill]
            for c in range(3):
                t = 0.0
                for q in range(nb):
                    t += Q[ill, c, q] * ui[6 + q]
                t *= s
                for b in range(nb):
                    y[6 + b] += Q[ill, c, b] * t
    return u, yu, np.array([l0, l1, l2]), jdx


@njit(parallel=True, cache=True, fastmath=True)
def lower_products(
    yu: np.ndarray,
    dA: np.ndarray,
    dn_t_indptr: np.ndarray,
    dn_t_row: np.ndarray,
    dn_t_blocks: np.ndarray,
    jg_t_blocks: np.ndarray,
    jdx: np.ndarray,
    lap_indptr: np.ndarray,
    lap_col: np.ndarray,
    lap_val: np.ndarray,
    spectral: np.ndarray,
    photometric: np.ndarray,
    ox: np.ndarray,
    oa: np.ndarray,
) -> None:
    """Second half of ``Linearisation.matvec``: back from u to [x, α], written into ``ox``
    (N, 3) and ``oa`` (N, N_b) (views of the product, so it needs no packing):
    ``x_j = yu_j[:3] + Σ_i D_ijᵀ yu_i[3:6] + Σ_i J_g(i, j)ᵀ (J_g δx)_i`` and
    ``α_j = yu_j[6:] + δα_j S + (L δα)_j Bᵀ B`` (S = γ1 R_sᵀR_s, ``photometric`` = R_bᵀR_b).
    The transpose runs over copies of the blocks stored column by column (``dn_t_*``,
    ``jg_t_blocks``: the transpose's CSR), so every vertex writes only its own rows and reads
    its blocks in sequence (gathering them by index from the row-ordered arrays made this
    product memory-latency bound: 61 → 36 ms on one core at 100k; sums in registers and
    contiguous inner loops: 36 → 24 ms); ``jdx`` = J_g δx (N,) from :func:`gram_products`
    (empty: the geometric rows are left out). Empty ``dn_t_blocks``: positions fixed."""
    n, k = yu.shape
    nb = dA.shape[1]
    with_normals = dn_t_blocks.shape[0] > 0
    with_geometric = jdx.shape[0] > 0
    lap_a = np.empty((n, nb))  # (L δα)_j, preallocated: no heap allocation per vertex
    for j in prange(n):
        x0, x1, x2 = yu[j, 0], yu[j, 1], yu[j, 2]
        if with_normals:
            for t in range(dn_t_indptr[j], dn_t_indptr[j + 1]):
                i = dn_t_row[t]
                y3, y4, y5 = yu[i, 3], yu[i, 4], yu[i, 5]
                dn = dn_t_blocks[t]
                x0 += dn[0, 0] * y3 + dn[1, 0] * y4 + dn[2, 0] * y5
                x1 += dn[0, 1] * y3 + dn[1, 1] * y4 + dn[2, 1] * y5
                x2 += dn[0, 2] * y3 + dn[1, 2] * y4 + dn[2, 2] * y5
                if with_geometric:
                    jd = jdx[i]
                    x0 += jg_t_blocks[t, 0] * jd
                    x1 += jg_t_blocks[t, 1] * jd
                    x2 += jg_t_blocks[t, 2] * jd
        ox[j, 0], ox[j, 1], ox[j, 2] = x0, x1, x2
        la = lap_a[j]
        for b in range(nb):
            la[b] = 0.0
        for t in range(lap_indptr[j], lap_indptr[j + 1]):
            m, v = lap_col[t], lap_val[t]
            for b in range(nb):
                la[b] += v * dA[m, b]
        o = oa[j]
        for b in range(nb):
            o[b] = yu[j, 6 + b]
        for q in range(nb):  # Σ_q by rows of S and BᵀB: a contiguous inner loop
            d, lq = dA[j, q], la[q]
            for b in range(nb):
                o[b] += d * spectral[q, b] + lq * photometric[q, b]


@njit(parallel=True, cache=True, fastmath=True)
def solve_vertex_blocks(
    inverse: np.ndarray, shapes: np.ndarray, vx: np.ndarray, va: np.ndarray
) -> np.ndarray:
    """``inverse[i] @ [shapes[i]ᵀ vx[i], va[i]]`` for every vertex i: the block
    preconditioner's vertex part, once per CG iteration. ``inverse`` (N, m + N_b, m + N_b)
    acts on [x or h, α]; ``shapes`` (N, 3, m) maps the block's m position unknowns to x (the
    identity, or the vertex's normal when it moves along it). NumPy's einsums over these tiny
    blocks took longer than the matvec at 130k vertices."""
    n, k = inverse.shape[0], inverse.shape[1]
    m = shapes.shape[2]
    out = np.empty((n, k))
    for i in prange(n):
        for r in range(k):
            acc = 0.0
            for j in range(m):
                acc += inverse[i, r, j] * (
                    shapes[i, 0, j] * vx[i, 0]
                    + shapes[i, 1, j] * vx[i, 1]
                    + shapes[i, 2, j] * vx[i, 2]
                )
            for b in range(k - m):
                acc += inverse[i, r, m + b] * va[i, b]
            out[i, r] = acc
    return out


@njit(parallel=True, cache=True, fastmath=True)
def expand_positions(shapes: np.ndarray, z: np.ndarray) -> np.ndarray:
    """x (N, 3) of the block unknowns ``z[:, :m]``: ``shapes[i] @ z[i, :m]`` per vertex."""
    n, m = shapes.shape[0], shapes.shape[2]
    out = np.empty((n, 3))
    for i in prange(n):
        for a in range(3):
            acc = 0.0
            for j in range(m):
                acc += shapes[i, a, j] * z[i, j]
            out[i, a] = acc
    return out


@njit(parallel=True, cache=True, fastmath=True)
def coupling_transpose_product(coupling: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``Σ_i C_iᵀ z_i`` (3,) over the vertices' light couplings ``C`` (N, k, 3): the block
    preconditioner's light right-hand side, without BLAS's single-threaded (N·k × 3) pass."""
    n, k = z.shape
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for i in prange(n):
        for r in range(k):
            s0 += coupling[i, r, 0] * z[i, r]
            s1 += coupling[i, r, 1] * z[i, r]
            s2 += coupling[i, r, 2] * z[i, r]
    return np.array([s0, s1, s2])


@njit(parallel=True, cache=True, fastmath=True)
def eliminate_shared_light(
    inverse: np.ndarray,
    coupling: np.ndarray,
    shapes: np.ndarray,
    alpha_mask: np.ndarray,
    light_mask: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The block preconditioner's light elimination for a shared light, one pass per vertex:
    the coupling in the block's unknowns ``C̃_i = B_iᵀ C_i`` (N, m + N_b, 3) from ``coupling``
    C (N, 3 + N_b, 3) over [x, α] (B_i as in :func:`damped_block_inverses`, the light's columns
    masked by ``light_mask`` (3,) 1 = free), ``D_i⁻¹ C̃_i`` (N, m + N_b, 3) with the block
    inverses ``inverse``, and per vertex ``C̃_iᵀ D_i⁻¹ C̃_i`` (N, 3, 3), whose sum the Schur
    complement subtracts. NumPy's batched products over these tiny blocks took 95 ms at 100k."""
    n, k = inverse.shape[0], inverse.shape[1]
    m = shapes.shape[2]
    nb = k - m
    reduced = np.empty((n, k, 3))
    dinv_c = np.empty((n, k, 3))
    schur_terms = np.empty((n, 3, 3))
    for i in prange(n):
        c = reduced[i]
        for j in range(m):
            for d in range(3):
                c[j, d] = light_mask[d] * (
                    shapes[i, 0, j] * coupling[i, 0, d]
                    + shapes[i, 1, j] * coupling[i, 1, d]
                    + shapes[i, 2, j] * coupling[i, 2, d]
                )
        for b in range(nb):
            for d in range(3):
                c[m + b, d] = light_mask[d] * alpha_mask[i, b] * coupling[i, 3 + b, d]
        e = dinv_c[i]
        for r in range(k):
            e0 = 0.0
            e1 = 0.0
            e2 = 0.0
            for q in range(k):
                v = inverse[i, r, q]
                e0 += v * c[q, 0]
                e1 += v * c[q, 1]
                e2 += v * c[q, 2]
            e[r, 0], e[r, 1], e[r, 2] = e0, e1, e2
        for d in range(3):
            for f in range(3):
                acc = 0.0
                for r in range(k):
                    acc += c[r, d] * e[r, f]
                schur_terms[i, d, f] = acc
    return reduced, dinv_c, schur_terms


@njit(inline="always", cache=True, fastmath=True)
def _light_corrected(z: np.ndarray, dinv_c: np.ndarray, light: np.ndarray, i: int, r: int) -> float:
    """``z[i, r] − (D_i⁻¹ C_i)[r] · δl``."""
    return z[i, r] - (
        dinv_c[i, r, 0] * light[0] + dinv_c[i, r, 1] * light[1] + dinv_c[i, r, 2] * light[2]
    )


@njit(parallel=True, cache=True, fastmath=True)
def back_substitute_light(
    z: np.ndarray,
    dinv_c: np.ndarray,
    light: np.ndarray,
    shapes: np.ndarray,
    alpha_mask: np.ndarray,
    out_x: np.ndarray,
    out_a: np.ndarray,
) -> None:
    """``z_i − (D_i⁻¹ C_i) δl`` per vertex, written as x (``shapes[i]`` times its position
    unknowns) into ``out_x`` (N, 3) and as masked α into ``out_a`` (N, N_b): the block
    preconditioner's last step and its scatter into θ's layout in one pass (views of θ)."""
    n, k = z.shape
    m = shapes.shape[2]
    for i in prange(n):
        x0 = 0.0
        x1 = 0.0
        x2 = 0.0
        for j in range(m):  # each position unknown corrected once, then spread over x, y, z
            zj = _light_corrected(z, dinv_c, light, i, j)
            x0 += shapes[i, 0, j] * zj
            x1 += shapes[i, 1, j] * zj
            x2 += shapes[i, 2, j] * zj
        out_x[i, 0] = x0
        out_x[i, 1] = x1
        out_x[i, 2] = x2
        for b in range(k - m):
            out_a[i, b] = _light_corrected(z, dinv_c, light, i, m + b) * alpha_mask[i, b]


@njit(parallel=True, cache=True)
def project_points(
    X: np.ndarray,
    vertex: np.ndarray,
    view: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    camera: np.ndarray,
    distortion: np.ndarray,
    gradient: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (P, 2) of the points ``X[vertex]`` in views ``view`` (P,), and with
    ``gradient`` ``∂uv/∂x`` (P, 2, 3) (else empty), in one pass: the optimiser projects every
    (vertex, view) pair at each evaluation, and NumPy's passes over (P, 2, 3) arrays took a
    tenth of the solve. Per view: world->camera ``R`` (V, 3, 3), ``t`` (V, 3); ``camera``
    (V, 4) = fx, fy, cx, cy; ``distortion`` (V, 4) = OpenCV k1, k2, p1, p2
    (:meth:`Intrinsics.distortion`). A compiled copy of :meth:`Intrinsics.project_camera`
    (points on or behind the camera plane project to NaN); ``test_sampling.py`` holds the two
    equal."""
    n = vertex.size
    uv = np.empty((n, 2))
    duv = np.empty((n if gradient else 0, 2, 3))
    for p in prange(n):
        i, c = vertex[p], view[p]
        w0, w1, w2 = X[i, 0], X[i, 1], X[i, 2]
        xc0 = R[c, 0, 0] * w0 + R[c, 0, 1] * w1 + R[c, 0, 2] * w2 + t[c, 0]
        xc1 = R[c, 1, 0] * w0 + R[c, 1, 1] * w1 + R[c, 1, 2] * w2 + t[c, 1]
        z = R[c, 2, 0] * w0 + R[c, 2, 1] * w1 + R[c, 2, 2] * w2 + t[c, 2]
        k1, k2, p1, p2 = distortion[c, 0], distortion[c, 1], distortion[c, 2], distortion[c, 3]
        fx, fy = camera[c, 0], camera[c, 1]
        # normalised coordinates and the radial factor, shared by the pixel and its Jacobian
        inv_z = 1.0 / (z if abs(z) > 1e-12 else 1e-12)
        x, y = xc0 * inv_z, xc1 * inv_z
        r2 = x * x + y * y
        radial = 1.0 + k1 * r2 + k2 * r2 * r2
        if z > 0.0:
            uv[p, 0] = fx * (x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)) + camera[c, 2]
            uv[p, 1] = fy * (y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y) + camera[c, 3]
        else:
            uv[p, 0] = uv[p, 1] = np.nan
        if not gradient:
            continue
        # ∂(x, y)/∂x_c = (1/z) [[1, 0, −x], [0, 1, −y]]; the distortion's 2×2 on the left
        slope = 2.0 * (k1 + 2.0 * k2 * r2)
        cross = slope * x * y + 2.0 * p1 * x + 2.0 * p2 * y
        a = radial + slope * x * x + 2.0 * p1 * y + 6.0 * p2 * x
        d = radial + slope * y * y + 6.0 * p1 * y + 2.0 * p2 * x
        a0, a1, a2 = fx * a * inv_z, fx * cross * inv_z, -fx * (a * x + cross * y) * inv_z
        b0, b1, b2 = fy * cross * inv_z, fy * d * inv_z, -fy * (cross * x + d * y) * inv_z
        for col in range(3):
            duv[p, 0, col] = a0 * R[c, 0, col] + a1 * R[c, 1, col] + a2 * R[c, 2, col]
            duv[p, 1, col] = b0 * R[c, 0, col] + b1 * R[c, 1, col] + b2 * R[c, 2, col]
    return uv, duv


@njit(parallel=True, cache=True, fastmath=True)
def rendered_error(
    colours: np.ndarray,
    pair_shading: np.ndarray,
    obs_pair: np.ndarray,
    vertex: np.ndarray,
    illumination: np.ndarray,
    observed: np.ndarray,
) -> np.ndarray:
    """Per observation the error s c − y_obs (M, 3), with s its pair's shading and c
    ``colours[ill, vertex]``, in one pass (no per-observation s or c is kept: 0.15 GB at 5M
    observations)."""
    m_count = obs_pair.size
    error = np.empty((m_count, 3))
    for m in prange(m_count):
        sm = pair_shading[obs_pair[m]]
        for ch in range(3):
            error[m, ch] = sm * colours[illumination[m], vertex[m], ch] - observed[m, ch]
    return error


@njit(parallel=True, cache=True, fastmath=True)
def damped_block_inverses(
    blocks: np.ndarray, damping: np.ndarray, shapes: np.ndarray, alpha_mask: np.ndarray
) -> np.ndarray:
    """Inverses (N, m + N_b, m + N_b) of the projected, damped vertex blocks
    ``Bᵢᵀ (blocks[i] + diag(damping[i])) Bᵢ`` with ``Bᵢ = diag(shapes[i], diag(alpha_mask[i]))``
    (``blocks`` (N, 3 + N_b, 3 + N_b) over [x, α]; ``shapes`` (N, 3, m) the position unknowns,
    ``alpha_mask`` (N, N_b) 1 = free). An unknown with no column (masked) gets a unit
    diagonal. The blocks are symmetric positive definite, so Gauss–Jordan needs no pivoting;
    in place, per vertex, it is ~20× faster than NumPy's batched inverse of these 9×9s."""
    n, m, nb = blocks.shape[0], shapes.shape[2], alpha_mask.shape[1]
    k = m + nb
    out = np.zeros((n, k, k))
    for i in prange(n):
        a = out[i]
        for r in range(m):
            for q in range(m):
                acc = 0.0
                for u in range(3):
                    for v in range(3):
                        acc += shapes[i, u, r] * blocks[i, u, v] * shapes[i, v, q]
                    acc += shapes[i, u, r] * damping[i, u] * shapes[i, u, q]
                a[r, q] = acc
            for b in range(nb):
                acc = 0.0
                for u in range(3):
                    acc += shapes[i, u, r] * blocks[i, u, 3 + b]
                a[r, m + b] = a[m + b, r] = acc * alpha_mask[i, b]
        for b in range(nb):
            for q in range(nb):
                a[m + b, m + q] = alpha_mask[i, b] * alpha_mask[i, q] * blocks[i, 3 + b, 3 + q]
            a[m + b, m + b] += alpha_mask[i, b] * damping[i, 3 + b]
        for r in range(k):
            if a[r, r] == 0.0:  # a masked unknown: its row and column are zero
                a[r, r] = 1.0
        for p in range(k):
            pivot = 1.0 / a[p, p]
            a[p, p] = 1.0
            for q in range(k):
                a[p, q] *= pivot
            for r in range(k):
                if r != p:
                    f = a[r, p]
                    a[r, p] = 0.0
                    for q in range(k):
                        a[r, q] -= f * a[p, q]
    return out


@njit(parallel=True, cache=True, fastmath=True)
def vertex_diagonal_blocks(
    gram: np.ndarray,
    shading2: np.ndarray,
    QtQ: np.ndarray,
    spectral: np.ndarray,
    lap_diag: np.ndarray,
    photometric: np.ndarray,
    dn_blocks: np.ndarray,
    geometric: np.ndarray,
    transpose_indptr: np.ndarray,
    transpose_row: np.ndarray,
) -> np.ndarray:
    """The diagonal blocks of JᵀJ per vertex j over [x (3), α (N_b)] (N, 3+N_b, 3+N_b):
    the gram's [x, α] rows and columns, the smoothness terms' α×α part ``S + L_jj Bᵀ B``
    (``spectral`` S = γ1 R_sᵀR_s, ``photometric`` = R_bᵀR_b), and what the normals and the
    geometric term add: x×x ``Σ_i D_ijᵀ G_nn(i) D_ij + J_g(i, j)ᵀ J_g(i, j)`` plus, from its own
    normal, ``G_xn D_jj + (G_xn D_jj)ᵀ``, and x×α ``D_jjᵀ G_nα``. The gram G over
    u = [x, n, α] comes as its position rows ``gram`` (N, 6, k) and α×α weights ``shading2``
    (N, K) of ``QtQ`` (K, N_b, N_b) (:func:`accumulate_normal_equations`); ``dn_blocks`` D
    (blocks, 3, 3) and ``geometric`` (blocks, 3) on the normal Jacobian's sparsity, stored
    column by column (the transpose's CSR: ``transpose_indptr``, rows ``transpose_row``); empty
    ``dn_blocks``: positions fixed. One pass: NumPy's slice copies and sums took 300 ms at
    100k, this 80."""
    n, k = gram.shape[0], gram.shape[2]
    nb = k - 6
    with_normals = dn_blocks.shape[0] > 0
    out = np.empty((n, 3 + nb, 3 + nb))
    for j in prange(n):
        o = out[j]
        for r in range(3):
            for q in range(3):
                o[r, q] = gram[j, r, q]
            for a in range(nb):
                o[r, 3 + a] = gram[j, r, 6 + a]
                o[3 + a, r] = gram[j, r, 6 + a]
        for a in range(nb):
            for b in range(nb):
                o[3 + a, 3 + b] = spectral[a, b] + lap_diag[j] * photometric[a, b]
        for ill in range(QtQ.shape[0]):
            s2 = shading2[j, ill]
            for a in range(nb):
                for b in range(nb):
                    o[3 + a, 3 + b] += s2 * QtQ[ill, a, b]
        if not with_normals:
            continue
        for t in range(transpose_indptr[j], transpose_indptr[j + 1]):
            i = transpose_row[t]
            for r in range(3):
                for q in range(3):
                    acc = geometric[t, r] * geometric[t, q]
                    for u in range(3):
                        gd = 0.0
                        for v in range(3):
                            gd += gram[i, 3 + u, 3 + v] * dn_blocks[t, v, q]
                        acc += dn_blocks[t, u, r] * gd
                    o[r, q] += acc
            if i != j:
                continue
            for r in range(3):
                for q in range(3):
                    cross = 0.0
                    for u in range(3):
                        cross += gram[j, r, 3 + u] * dn_blocks[t, u, q]
                    o[r, q] += cross
                    o[q, r] += cross
                for a in range(nb):
                    acc = 0.0
                    for u in range(3):
                        acc += dn_blocks[t, u, r] * gram[j, 3 + u, 6 + a]
                    o[r, 3 + a] += acc
                    o[3 + a, r] += acc
    return out


@njit(cache=True)
def face_normal_sums(x: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``ñ_i`` (N, 3): each face's (twice-area) normal added to its three corners, face by
    face (the order NumPy's per-component ``bincount`` summed in; one pass instead of three)."""
    out = np.zeros((x.shape[0], 3))
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        e0, e1, e2 = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
        g0, g1, g2 = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
        n0, n1, n2 = e1 * g2 - e2 * g1, e2 * g0 - e0 * g2, e0 * g1 - e1 * g0
        for v in (a, b, c):
            out[v, 0] += n0
            out[v, 1] += n1
            out[v, 2] += n2
    return out


@njit(parallel=True, cache=True)
def normal_jacobian_blocks(
    x: np.ndarray,
    faces: np.ndarray,
    inverse: np.ndarray,
    n_blocks: int,
    block_row: np.ndarray,
    normals: np.ndarray,
    inverse_length: np.ndarray,
) -> np.ndarray:
    """The blocks of ``∂n/∂X`` (see ``mesh.NormalJacobian``): per face the edge vector
    ``w`` of each (corner i, corner j) pair summed into block ``inverse[9f + 3i + j]``
    (serial: faces share blocks), then ``([w]_× − n (n × w)ᵀ) / |ñ|`` per block."""
    w = np.zeros((n_blocks, 3))
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        for j in range(3):  # ∂N/∂x_j = [x_p − x_q]_×: (c, b) for a, (a, c) for b, (b, a) for c
            p, q = (c, b) if j == 0 else ((a, c) if j == 1 else (b, a))
            for i in range(3):
                blk = inverse[9 * f + 3 * i + j]
                for d in range(3):
                    w[blk, d] += x[p, d] - x[q, d]
    out = np.empty((n_blocks, 3, 3))
    for t in prange(n_blocks):
        r = block_row[t]
        n0, n1, n2 = normals[r, 0], normals[r, 1], normals[r, 2]
        w0, w1, w2 = w[t, 0], w[t, 1], w[t, 2]
        c0, c1, c2 = n1 * w2 - n2 * w1, n2 * w0 - n0 * w2, n0 * w1 - n1 * w0  # n × w
        s = inverse_length[r]
        out[t, 0, 0] = (0.0 - n0 * c0) * s
        out[t, 0, 1] = (-w2 - n0 * c1) * s
        out[t, 0, 2] = (w1 - n0 * c2) * s
        out[t, 1, 0] = (w2 - n1 * c0) * s
        out[t, 1, 1] = (0.0 - n1 * c1) * s
        out[t, 1, 2] = (-w0 - n1 * c2) * s
        out[t, 2, 0] = (-w1 - n2 * c0) * s
        out[t, 2, 1] = (w0 - n2 * c1) * s
        out[t, 2, 2] = (0.0 - n2 * c2) * s
    return out


@njit(parallel=True, cache=True, fastmath=True)
def cg_step(x: np.ndarray, r: np.ndarray, d: np.ndarray, q: np.ndarray, step: float) -> float:
    """CG's update ``x += step d``, ``r −= step q`` in place, in one pass; returns |r|²
    (NumPy: four passes and two temporaries of the ~1M-entry vectors at 100k vertices)."""
    acc = 0.0
    for i in prange(x.shape[0]):
        x[i] += step * d[i]
        ri = r[i] - step * q[i]
        r[i] = ri
        acc += ri * ri
    return acc


@njit(parallel=True, cache=True, fastmath=True)
def cg_direction(d: np.ndarray, z: np.ndarray, beta: float) -> None:
    """CG's next search direction ``d = z + β d``, in place."""
    for i in prange(d.shape[0]):
        d[i] = z[i] + beta * d[i]


@njit(parallel=True, cache=True, fastmath=True)
def project_to_stage(
    v: np.ndarray, damping: np.ndarray, step: np.ndarray, mask: np.ndarray, directions: np.ndarray
) -> None:
    """In place: ``v = P (v + damping ⊙ step)`` with P the stage's projection — the mask, then
    each vertex's position (θ's first 3N entries) onto its direction ``d dᵀ`` (``directions``
    (N, 3); empty: free motion). Empty ``damping``: no damping term."""
    damped = damping.shape[0] > 0
    for i in prange(v.shape[0]):
        vi = v[i] + damping[i] * step[i] if damped else v[i]
        v[i] = vi if mask[i] else 0.0
    for i in prange(directions.shape[0]):
        s = v[3 * i] * directions[i, 0] + v[3 * i + 1] * directions[i, 1]
        s += v[3 * i + 2] * directions[i, 2]
        for a in range(3):
            v[3 * i + a] = directions[i, a] * s


@njit(parallel=True, cache=True, fastmath=True)
def shading_gradients(
    x: np.ndarray,
    normals: np.ndarray,
    lights: np.ndarray,
    pair_vertex: np.ndarray,
    pair_view: np.ndarray,
    pair_s: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The derivatives of the shading ``s = (p − x)·n / |p − x|³`` (``forward.shading``) per
    (vertex, view) pair: ``g = ∂s/∂p = n/|d|³ − 3 (d·n) d/|d|⁵`` (= −∂s/∂x with n fixed) and
    ``h = ∂s/∂n = d/|d|³`` with d = p − x, zero where the pair is unlit (``pair_s`` ≤ 0).
    One pass instead of a dozen NumPy temporaries of (pairs × 3)."""
    m = pair_vertex.shape[0]
    g = np.empty((m, 3))
    h = np.empty((m, 3))
    for t in prange(m):
        if not pair_s[t] > 0.0:
            for a in range(3):
                g[t, a] = 0.0
                h[t, a] = 0.0
            continue
        i, c = pair_vertex[t], pair_view[t]
        d0, d1, d2 = lights[c, 0] - x[i, 0], lights[c, 1] - x[i, 1], lights[c, 2] - x[i, 2]
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        dist2 = d0 * d0 + d1 * d1 + d2 * d2
        inv3 = 1.0 / (dist2 * np.sqrt(dist2))
        k = 3.0 * (d0 * n0 + d1 * n1 + d2 * n2) * inv3 / dist2
        g[t, 0], g[t, 1], g[t, 2] = n0 * inv3 - k * d0, n1 * inv3 - k * d1, n2 * inv3 - k * d2
        h[t, 0], h[t, 1], h[t, 2] = d0 * inv3, d1 * inv3, d2 * inv3
    return g, h
