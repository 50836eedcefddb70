"""The PatchMatch inner loops, compiled: plane hypotheses scored against source views, and the
red–black propagation sweep that updates a view's depth and normal maps in place.

Scoring one (pixel, plane) pair touches every window sample of every channel in every source
view, millions of times per view, so these loops are compiled with numba and run over image
rows in parallel. Cameras are pinhole here (images are undistorted before matching).

The score is a normalised cross-correlation with the window's best-fit *plane* of intensity
removed per channel (mean and linear ramp), not only its mean: the lamp rides on the camera,
so the smooth shading across a window changes its slope from view to view. Plain zero-mean NCC
reads that slope as texture and matches it, which misplaces the untextured interiors of
uniformly painted regions by millimetres; with the ramp removed such windows hold only noise
and are left out (``min_texture``), and only real texture (paint edges, detail) is matched.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

INVALID_COST = 2.0  # 1 - NCC ranges over [0, 2]; a window that leaves a source view gets this


@njit(cache=True, fastmath=True)
def ramp_basis(du: np.ndarray, dv: np.ndarray) -> tuple[float, float]:
    """Squared norms of the centred window offsets (the ramp basis is orthogonal on a
    symmetric window)."""
    return float(np.sum(du * du)), float(np.sum(dv * dv))


@njit(cache=True, fastmath=True)
def reference_window(
    image: np.ndarray, row: int, col: int, dr: np.ndarray, dc: np.ndarray,
    du2: float, dv2: float, out: np.ndarray,
) -> float:
    """The window of pixel (row, col) with each channel's plane of intensity removed, scaled
    to unit norm over all samples and channels, into ``out`` (J, C). Returns the residual's
    RMS relative to the window's mean level (its texture); 0 for a flat window."""
    n_samples, n_chan = out.shape
    level = 0.0
    total = 0.0
    for ch in range(n_chan):
        s = 0.0
        su = 0.0
        sv = 0.0
        for j in range(n_samples):
            value = image[row + dr[j], col + dc[j], ch]
            s += value
            su += value * dc[j]
            sv += value * dr[j]
        mean = s / n_samples
        gu = su / du2
        gv = sv / dv2
        level += abs(mean)
        for j in range(n_samples):
            r = image[row + dr[j], col + dc[j], ch] - mean - gu * dc[j] - gv * dr[j]
            out[j, ch] = r
            total += r * r
    if total <= 0.0 or level <= 0.0:
        return 0.0
    norm = np.sqrt(total)
    for ch in range(n_chan):
        for j in range(n_samples):
            out[j, ch] /= norm
    return norm / np.sqrt(n_samples * n_chan) / (level / n_chan)


@njit(cache=True, fastmath=True)
def _source_cost(
    u: float, v: float, H: np.ndarray, ref: np.ndarray, du: np.ndarray, dv: np.ndarray,
    du2: float, dv2: float, image: np.ndarray, sums: np.ndarray,
) -> float:
    """1 - NCC (intensity planes removed) of one reference window warped into one source
    image by the plane's homography ``H`` (reference pixel -> source pixel, pixel-corner
    coordinates). ``sums`` is scratch space (C, 4)."""
    n_samples, n_chan = ref.shape
    height, width = image.shape[0], image.shape[1]
    sums[:] = 0.0
    cross = 0.0
    for j in range(n_samples):
        x, y = u + du[j], v + dv[j]
        hz = H[2, 0] * x + H[2, 1] * y + H[2, 2]
        if hz <= 0.0:
            return INVALID_COST
        us = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / hz - 0.5
        vs = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / hz - 0.5
        if not (0.0 <= us < width - 1.0 and 0.0 <= vs < height - 1.0):
            return INVALID_COST
        c0, r0 = int(us), int(vs)
        fu, fv = us - c0, vs - r0
        w00, w01 = (1 - fv) * (1 - fu), (1 - fv) * fu
        w10, w11 = fv * (1 - fu), fv * fu
        for ch in range(n_chan):
            value = (w00 * image[r0, c0, ch] + w01 * image[r0, c0 + 1, ch]
                     + w10 * image[r0 + 1, c0, ch] + w11 * image[r0 + 1, c0 + 1, ch])
            sums[ch, 0] += value
            sums[ch, 1] += value * value
            sums[ch, 2] += value * du[j]
            sums[ch, 3] += value * dv[j]
            cross += ref[j, ch] * value  # ref is orthogonal to each channel's plane
    variance = 0.0
    for ch in range(n_chan):
        variance += (sums[ch, 1] - sums[ch, 0] * sums[ch, 0] / n_samples
                     - sums[ch, 2] * sums[ch, 2] / du2 - sums[ch, 3] * sums[ch, 3] / dv2)
    if variance <= 1e-30:
        return INVALID_COST
    return 1.0 - cross / np.sqrt(variance)


@njit(cache=True, fastmath=True)
def plane_cost(
    u: float, v: float, ray: np.ndarray, distance: float, normal: np.ndarray, ref: np.ndarray,
    du: np.ndarray, dv: np.ndarray, du2: float, dv2: float, K_inv: np.ndarray,
    images: np.ndarray, A: np.ndarray, b: np.ndarray, top_k: int,
    H: np.ndarray, costs: np.ndarray, sums: np.ndarray,
) -> float:
    """The mean of the ``top_k`` best sources' 1 - NCC for the plane through the point at
    ``distance`` along the pixel's unit ``ray`` with camera-frame ``normal``. ``H``, ``costs``
    and ``sums`` are scratch space."""
    nx, ny, nz = normal[0], normal[1], normal[2]
    rho = distance * (nx * ray[0] + ny * ray[1] + nz * ray[2])
    if rho >= 0.0 or distance <= 0.0:  # the plane faces away from the camera
        return INVALID_COST
    n_sources = images.shape[0]
    # points X on the plane n.X = rho map to A X + b = (A + b n^T / rho) X: a homography
    # H = (A + b n^T / rho) K^-1 from reference pixels to source pixels
    for s in range(n_sources):
        for r in range(3):
            m0 = A[s, r, 0] + b[s, r] * nx / rho
            m1 = A[s, r, 1] + b[s, r] * ny / rho
            m2 = A[s, r, 2] + b[s, r] * nz / rho
            H[r, 0] = m0 * K_inv[0, 0]
            H[r, 1] = m1 * K_inv[1, 1]
            H[r, 2] = m0 * K_inv[0, 2] + m1 * K_inv[1, 2] + m2
        costs[s] = _source_cost(u, v, H, ref, du, dv, du2, dv2, images[s], sums)
    costs[:n_sources].sort()
    k = min(top_k, n_sources)
    total = 0.0
    for s in range(k):
        total += costs[s]
    return total / k


def k_inverse(inv: np.ndarray) -> np.ndarray:
    """K⁻¹ of a pinhole (fx, fy, cx, cy)."""
    return np.array([[1.0 / inv[0], 0.0, -inv[2] / inv[0]],
                     [0.0, 1.0 / inv[1], -inv[3] / inv[1]],
                     [0.0, 0.0, 1.0]])


# Neighbours whose planes a pixel tries (Gipuma's red–black pattern: every offset has an odd
# coordinate sum, so a sweep over one colour reads only pixels of the other).
PROPAGATION = np.array([[0, 1], [0, -1], [1, 0], [-1, 0], [0, 5], [0, -5], [5, 0], [-5, 0],
                        [2, 3], [-2, -3], [3, -2], [-3, 2]], dtype=np.int64)


@njit(cache=True, fastmath=True)
def _facing(n: np.ndarray, ray: np.ndarray, cos_max: float) -> None:
    """Normalise ``n`` in place, flip it towards the camera and pull it inside the cone of
    half-angle arccos(cos_max) around the viewing ray."""
    norm = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    if norm < 1e-12:
        n[0], n[1], n[2] = -ray[0], -ray[1], -ray[2]
        return
    n /= norm
    dot = n[0] * ray[0] + n[1] * ray[1] + n[2] * ray[2]
    if dot > 0.0:
        n *= -1.0
        dot = -dot
    if -dot < cos_max:  # too oblique: halfway towards facing the camera
        n[0] -= ray[0]
        n[1] -= ray[1]
        n[2] -= ray[2]
        n /= np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])


@njit(parallel=True, cache=True, fastmath=True)
def sweep(
    colour: int, image: np.ndarray, active: np.ndarray, rays: np.ndarray,
    lo: np.ndarray, hi: np.ndarray, distance: np.ndarray, normal: np.ndarray, cost: np.ndarray,
    dr: np.ndarray, dc: np.ndarray, K_inv: np.ndarray, images: np.ndarray, A: np.ndarray,
    b: np.ndarray, top_k: int, noise: np.ndarray, depth_step: float, normal_step: float,
    cos_max: float, explore: bool,
) -> None:
    """One half of a PatchMatch iteration over the pixels of one checkerboard ``colour``
    ((row + col) % 2), updating ``distance``, ``normal`` and ``cost`` in place.

    Each active pixel tries the planes of its :data:`PROPAGATION` neighbours (that plane cut
    by its own ray), then refinements of its own: the distance moved by up to
    ``depth_step`` (fraction of its search range) with the normal tilted by up to
    ``normal_step``, each of the two alone, and (with ``explore``) a uniformly random plane;
    ``noise`` (H, W, 9) holds the random draws in [-1, 1), so a run is reproducible whatever
    the thread count.
    ``dr, dc`` are the window's row/column offsets (the window must stay inside the image for
    active pixels)."""
    h, w = active.shape
    du = dc.astype(np.float64)
    dv = dr.astype(np.float64)
    du2, dv2 = ramp_basis(du, dv)
    n_chan = image.shape[2]
    for row in prange(h):
        ref = np.empty((len(dr), n_chan))
        H = np.empty((3, 3))
        costs = np.empty(images.shape[0])
        sums = np.empty((n_chan, 4))
        trial = np.empty(3)
        for col in range((row + colour) % 2, w, 2):
            if not active[row, col]:
                continue
            if reference_window(image, row, col, dr, dc, du2, dv2, ref) <= 0.0:
                continue
            u, v = col + 0.5, row + 0.5
            ray = rays[row, col]
            best_d, best_c = distance[row, col], cost[row, col]
            best_n = normal[row, col].copy()
            for k in range(len(PROPAGATION)):
                r2, c2 = row + PROPAGATION[k, 0], col + PROPAGATION[k, 1]
                if r2 < 0 or r2 >= h or c2 < 0 or c2 >= w or not active[r2, c2]:
                    continue
                if cost[r2, c2] >= best_c:
                    continue
                m = normal[r2, c2]
                ray2 = rays[r2, c2]
                rho = distance[r2, c2] * (m[0] * ray2[0] + m[1] * ray2[1] + m[2] * ray2[2])
                along = m[0] * ray[0] + m[1] * ray[1] + m[2] * ray[2]
                if along >= -1e-6:
                    continue
                d = rho / along
                if d < lo[row, col] or d > hi[row, col]:
                    continue
                if abs(d - best_d) < 1e-9 and (m[0] * best_n[0] + m[1] * best_n[1]
                                               + m[2] * best_n[2]) > 1.0 - 1e-12:
                    continue
                c = plane_cost(u, v, ray, d, m, ref, du, dv, du2, dv2, K_inv, images, A, b,
                               top_k, H, costs, sums)
                if c < best_c:
                    best_c, best_d = c, d
                    best_n[:] = m
            span = hi[row, col] - lo[row, col]
            z = noise[row, col]
            for kind in range(4 if explore else 3):
                if kind == 3:  # a fresh random plane: escapes a bad start
                    d = lo[row, col] + 0.5 * (z[5] + 1.0) * span
                    trial[0], trial[1], trial[2] = z[6] - ray[0], z[7] - ray[1], z[8] - ray[2]
                else:  # 0: distance and normal, 1: normal, 2: distance
                    d = best_d + (depth_step * span * z[kind] if kind != 1 else 0.0)
                    trial[:] = best_n
                    if kind != 2:
                        trial[0] += normal_step * z[2]
                        trial[1] += normal_step * z[3]
                        trial[2] += normal_step * z[4]
                if d < lo[row, col] or d > hi[row, col]:
                    continue
                _facing(trial, ray, cos_max)
                c = plane_cost(u, v, ray, d, trial, ref, du, dv, du2, dv2, K_inv, images, A,
                               b, top_k, H, costs, sums)
                if c < best_c:
                    best_c, best_d = c, d
                    best_n[:] = trial
            distance[row, col], cost[row, col] = best_d, best_c
            normal[row, col] = best_n


@njit(parallel=True, cache=True, fastmath=True)
def texture_map(image: np.ndarray, active: np.ndarray, dr: np.ndarray, dc: np.ndarray
                ) -> np.ndarray:
    """Each active pixel's window texture (:func:`reference_window`), 0 elsewhere."""
    h, w = active.shape
    du, dv = dc.astype(np.float64), dr.astype(np.float64)
    du2, dv2 = ramp_basis(du, dv)
    out = np.zeros((h, w))
    for row in prange(h):
        ref = np.empty((len(dr), image.shape[2]))
        for col in range(w):
            if active[row, col]:
                out[row, col] = reference_window(image, row, col, dr, dc, du2, dv2, ref)
    return out


@njit(parallel=True, cache=True, fastmath=True)
def evaluate(
    image: np.ndarray, active: np.ndarray, rays: np.ndarray, distance: np.ndarray,
    normal: np.ndarray, dr: np.ndarray, dc: np.ndarray, K_inv: np.ndarray, images: np.ndarray,
    A: np.ndarray, b: np.ndarray, top_k: int,
) -> np.ndarray:
    """The cost (H, W) of every active pixel's current plane; INVALID_COST elsewhere."""
    h, w = active.shape
    du, dv = dc.astype(np.float64), dr.astype(np.float64)
    du2, dv2 = ramp_basis(du, dv)
    out = np.full((h, w), INVALID_COST)
    for row in prange(h):
        ref = np.empty((len(dr), image.shape[2]))
        H = np.empty((3, 3))
        costs = np.empty(images.shape[0])
        sums = np.empty((image.shape[2], 4))
        for col in range(w):
            if active[row, col] and reference_window(image, row, col, dr, dc, du2, dv2,
                                                     ref) > 0.0:
                out[row, col] = plane_cost(col + 0.5, row + 0.5, rays[row, col],
                                           distance[row, col], normal[row, col], ref, du, dv,
                                           du2, dv2, K_inv, images, A, b, top_k, H, costs,
                                           sums)
    return out
