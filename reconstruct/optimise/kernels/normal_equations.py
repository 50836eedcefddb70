"""Compiled Gauss–Newton accumulation of :meth:`~reconstruct.optimise.cost.JointCost.linearise`:
one loop per vertex reads each of its observations once (sorted by vertex, view, frame, so a
vertex's pairs and a pair's frames are contiguous) and keeps the sums in registers, instead of
one (observations × ·) NumPy temporary per intermediate quantity."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


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
    (N, K), stored as those K numbers instead of N_b² (less than half the memory) —
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
    product memory-latency bound); ``jdx`` = J_g δx (N,) from :func:`gram_products`
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
    ``dn_blocks``: positions fixed. One pass instead of NumPy's slice copies and sums."""
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
