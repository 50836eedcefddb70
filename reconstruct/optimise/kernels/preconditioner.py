"""Compiled parts of the solver's block preconditioner: the damped per-vertex block inverses,
their solves, and the elimination and back-substitution of a shared light."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True, fastmath=True)
def damped_block_inverses(
    blocks: np.ndarray, damping: np.ndarray, shapes: np.ndarray, alpha_mask: np.ndarray
) -> np.ndarray:
    """Inverses (N, m + N_b, m + N_b) of the projected, damped vertex blocks
    ``Bᵢᵀ (blocks[i] + diag(damping[i])) Bᵢ`` with ``Bᵢ = diag(shapes[i], diag(alpha_mask[i]))``
    (``blocks`` (N, 3 + N_b, 3 + N_b) over [x, α]; ``shapes`` (N, 3, m) the position unknowns,
    ``alpha_mask`` (N, N_b) 1 = free). An unknown with no column (masked) gets a unit
    diagonal. The blocks are symmetric positive definite, so Gauss–Jordan needs no pivoting;
    in place, per vertex, it beats NumPy's batched inverse of these small blocks."""
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
def solve_vertex_blocks(
    inverse: np.ndarray, shapes: np.ndarray, vx: np.ndarray, va: np.ndarray
) -> np.ndarray:
    """``inverse[i] @ [shapes[i]ᵀ vx[i], va[i]]`` for every vertex i: the block
    preconditioner's vertex part, once per CG iteration. ``inverse`` (N, m + N_b, m + N_b)
    acts on [x or h, α]; ``shapes`` (N, 3, m) maps the block's m position unknowns to x (the
    identity, or the vertex's normal when it moves along it). Compiled: NumPy's einsums over
    these tiny blocks cost more than the matvec."""
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
    complement subtracts. Compiled, as NumPy's batched products over tiny blocks are slow."""
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
