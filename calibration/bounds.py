"""Physically valid reflectance: ``lower ≤ B α ≤ upper`` at every wavelength, as a constraint on
the basis weights α that the estimators solve under, not a clip of their answers.

A reflectance below 0 or above 1 is no measurement, and clipping ``B α`` afterwards leaves the
basis (and the colour the fit chose). So each estimate is the minimiser of its own quadratic
over the polytope ``{α : lower ≤ B α ≤ upper}``: a small strictly convex QP per pixel or vertex
(N_b unknowns, 2 N_λ inequality rows, at most N_b of them active), solved by a primal active-set
method (Nocedal & Wright, Algorithm 16.3) compiled with numba. Every iterate is feasible, so the
answer is valid even where the iteration limit stops it. Rows whose unconstrained answer already
lies inside the bounds are left as they are.

>>> import numpy as np
>>> from calibration.basis import default_basis
>>> basis = default_basis()
>>> alpha = basis.project(np.linspace(-0.2, 1.2, 31))  # a ramp below 0 and above 1
>>> r = basis.reconstruct(project(alpha[None], basis.B))
>>> bool(r.min() >= 0.0 and r.max() <= 1.0)
True
"""

from __future__ import annotations

import numba
import numpy as np

from core.errors import RigError

_ITERATIONS = 200  # active-set steps per row; a row needs about as many as it has active bounds
_STEP_TOL = 1e-13  # a working-set step this short is the constrained minimiser
_GREY = 0.5  # the start of rows with no feasible start: mid-grey lies inside every bound pair
# A row this close to its bounds counts as inside: the active set's own round-off, which
# solving the row again would only move by as much.
ROUND_OFF = 1e-10


def constraint_rows(
    B: np.ndarray, lower: float = 0.0, upper: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """The bounds as ``G α ≥ h``: ``B α ≥ lower`` then ``−B α ≥ −upper`` (an infinite bound gives
    rows that never bind)."""
    B = np.asarray(B, dtype=float)
    n = B.shape[0]
    return np.concatenate([B, -B]), np.concatenate([np.full(n, lower), np.full(n, -upper)])


def violation(
    alpha: np.ndarray, B: np.ndarray, lower: float = 0.0, upper: float = 1.0
) -> np.ndarray:
    """How far each row's ``B α`` leaves ``[lower, upper]`` (0 inside), (P,)."""
    r = np.asarray(alpha, dtype=float) @ np.asarray(B, dtype=float).T
    return np.maximum(
        np.max(lower - r, axis=-1, initial=0.0), np.max(r - upper, axis=-1, initial=0.0)
    )


def grey_weights(B: np.ndarray, lower: float = 0.0, upper: float = 1.0) -> np.ndarray:
    """Basis weights of the best grey the basis holds, checked strictly inside the bounds: the
    feasible start of rows that have none."""
    B = np.asarray(B, dtype=float)
    level = _GREY if np.isinf(upper) else 0.5 * (lower + upper)
    grey = np.linalg.lstsq(B, np.full(B.shape[0], level), rcond=None)[0]
    r = B @ grey
    if not (np.all(np.isfinite(r)) and r.min() > lower and r.max() < upper):
        raise RigError(
            f"the spectral basis cannot represent a grey inside [{lower:g}, {upper:g}] "
            f"(its best grey spans {r.min():.3g}..{r.max():.3g})",
            "build the basis from real reflectances (`rig calibrate basis`), whose first "
            "component is close to flat",
        )
    return grey


def bounded_quadratic(
    hessian: np.ndarray,
    linear: np.ndarray,
    B: np.ndarray,
    lower: float = 0.0,
    upper: float = 1.0,
    start: np.ndarray | None = None,
    unconstrained: np.ndarray | None = None,
) -> np.ndarray:
    """Per row p: ``argmin ½ αᵀ H_p α − f_pᵀ α`` subject to ``lower ≤ B α ≤ upper``.

    ``hessian`` (P, N_b, N_b), or one (N_b, N_b) shared by every row, symmetric positive definite;
    ``linear`` f (P, N_b). ``unconstrained`` (P, N_b), when the caller has it, is the minimiser
    without bounds: rows where it is feasible keep it. ``start`` (P, N_b): a feasible point per
    row to start from (infeasible ones start at :func:`grey_weights`). Rows with a non-finite
    ``linear`` come back as NaN.
    """
    f = np.atleast_2d(np.asarray(linear, dtype=float))
    h = np.asarray(hessian, dtype=float)
    shared = h.ndim == 2
    hs = np.ascontiguousarray(h[None] if shared else h)
    if unconstrained is None:
        if shared:
            x = np.linalg.solve(hs[0], f.T).T
        else:
            x = np.linalg.solve(hs, f[..., None])[..., 0]
    else:
        x = np.array(unconstrained, dtype=float)
    out = x.copy()
    finite = np.all(np.isfinite(f), axis=1)
    out[~finite] = np.nan
    outside = violation(np.where(np.isfinite(x), x, 0.0), B, lower, upper) > ROUND_OFF
    rows = np.flatnonzero(finite & outside)
    if rows.size == 0:
        return out
    G, hb = constraint_rows(B, lower, upper)
    grey = grey_weights(B, lower, upper)
    x0 = np.broadcast_to(grey, (rows.size, grey.size)).copy()
    if start is not None:
        s = np.asarray(start, dtype=float)[rows]
        ok = np.all(np.isfinite(s), axis=1) & (violation(s, B, lower, upper) <= ROUND_OFF)
        x0[ok] = s[ok]
    which = np.zeros(rows.size, dtype=np.int64) if shared else rows.astype(np.int64)
    out[rows] = _active_set_rows(hs, which, f[rows], G, hb, x0, _ITERATIONS)
    return out


def project(
    alpha: np.ndarray,
    B: np.ndarray,
    lower: float = 0.0,
    upper: float = 1.0,
    start: np.ndarray | None = None,
) -> np.ndarray:
    """The nearest weights (in reflectance, ``‖B (α' − α)‖``) whose reflectance lies within the
    bounds, per row of ``alpha`` (P, N_b); rows already inside are returned unchanged."""
    a = np.atleast_2d(np.asarray(alpha, dtype=float))
    B = np.asarray(B, dtype=float)
    btb = B.T @ B
    return bounded_quadratic(btb, a @ btb, B, lower, upper, start, unconstrained=a)


@numba.njit(cache=True)
def _active_set_rows(
    hessians: np.ndarray,
    which: np.ndarray,
    linear: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    start: np.ndarray,
    iterations: int,
) -> np.ndarray:  # pragma: no cover - compiled
    out = np.empty_like(start)
    for r in range(start.shape[0]):
        out[r] = _active_set(hessians[which[r]], linear[r], G, h, start[r], iterations)
    return out


@numba.njit(cache=True)
def _active_set(
    H: np.ndarray, f: np.ndarray, G: np.ndarray, h: np.ndarray, x0: np.ndarray, iterations: int
) -> np.ndarray:  # pragma: no cover - compiled
    """Primal active set for ``min ½xᵀHx − fᵀx, G x ≥ h`` from the feasible ``x0``.

    Each step solves the equality-constrained problem on the working set W through its KKT
    system; a zero step with all multipliers ≥ 0 is optimal, a negative multiplier leaves W,
    and a step is cut at the first constraint it would cross, which joins W. A row entering W
    is never a combination of W's rows (it has a non-zero product with a step W's rows annul),
    so the KKT matrix stays regular."""
    n = x0.size
    m = G.shape[0]
    x = x0.copy()
    active = np.zeros(m, dtype=np.bool_)
    for _ in range(iterations):
        work = np.flatnonzero(active)
        k = work.size
        kkt = np.zeros((n + k, n + k))
        kkt[:n, :n] = H
        rhs = np.zeros(n + k)
        rhs[:n] = f - H @ x
        for j in range(k):
            kkt[:n, n + j] = -G[work[j]]
            kkt[n + j, :n] = G[work[j]]
        try:
            sol = np.linalg.solve(kkt, rhs)
        except Exception:  # a near-singular H: the least-squares step
            sol = np.linalg.lstsq(kkt, rhs)[0]
        p = sol[:n]
        if np.max(np.abs(p)) <= _STEP_TOL * (1.0 + np.max(np.abs(x))):
            if k == 0:
                break
            mu = sol[n:]
            leave = np.argmin(mu)
            if mu[leave] >= 0.0:
                break
            active[work[leave]] = False
            continue
        step = 1.0
        blocking = -1
        gp = G @ p
        gx = G @ x
        # a row nearly orthogonal to the step is no block (and would make W dependent)
        tiny = _STEP_TOL * np.sqrt(np.sum(p * p))
        for i in range(m):
            if not active[i] and gp[i] < -tiny * np.sqrt(np.sum(G[i] * G[i])):
                reach = (h[i] - gx[i]) / gp[i]
                if reach < step:
                    step = max(reach, 0.0)
                    blocking = i
        x += step * p
        if blocking >= 0:
            active[blocking] = True
    return x


def bounded_band(
    reflectance: np.ndarray,
    std: np.ndarray,
    lower: float = 0.0,
    upper: float = 1.0,
    coverage: float = 0.95,
) -> tuple[np.ndarray, np.ndarray]:
    """The shortest interval holding ``coverage`` of a normal ``N(reflectance, std²)`` truncated
    to ``[lower, upper]``, per sample: an uncertainty band that, like the reflectance, never
    leaves the physical range (±2σ would reach below 0 or above 1) and always holds the estimate
    (the truncated density's mode). ±1.96σ away from the bounds; NaN where ``std`` is.

    >>> low, high = bounded_band(np.array([0.0, 0.5]), np.array([0.05, 0.05]))
    >>> round(float(low[0]), 3), round(float(high[0]), 3), round(float(high[1] - low[1]), 3)
    (0.0, 0.098, 0.196)
    """
    from scipy.special import ndtr, ndtri

    r = np.asarray(reflectance, dtype=float)
    s = np.asarray(std, dtype=float)
    ok = np.isfinite(s) & np.isfinite(r) & (s > 0)
    low, high = np.full(r.shape, np.nan), np.full(r.shape, np.nan)
    flat = np.isfinite(s) & np.isfinite(r) & (s == 0)
    low[flat] = high[flat] = r[flat]
    mean, sd = np.clip(r[ok], lower, upper), s[ok]
    a, b = ndtr((lower - mean) / sd), ndtr((upper - mean) / sd)  # the range's ends, in Φ
    need = coverage * (b - a)  # the untruncated mass the band must hold
    with np.errstate(invalid="ignore", divide="ignore"):
        # the density falls off symmetrically from the mean: the band grows equally on both
        # sides until it meets a bound, then only on the other side (half-widths in σ)
        both = ndtri(0.5 + 0.5 * need)
        up_only = ndtri(a + need)  # the band starts at `lower`
        down_only = -ndtri(b - need)  # the band ends at `upper`
    lo, hi = mean - both * sd, mean + both * sd
    nearer_lower = mean - lower <= upper - mean  # the bound a growing band meets first
    starts_low = (lo < lower) & ((hi <= upper) | nearer_lower)
    ends_high = (hi > upper) & ((lo >= lower) | ~nearer_lower)
    lo = np.where(starts_low, lower, np.where(ends_high, mean - down_only * sd, lo))
    hi = np.where(ends_high, upper, np.where(starts_low, mean + up_only * sd, hi))
    low[ok], high[ok] = np.clip(lo, lower, upper), np.clip(hi, lower, upper)
    return low, high
