"""2-D spectral reflectance estimation from K illuminations × RGB (regularised least squares).

Per pixel p, with response matrices ``A_k = Cᵀ diag(L_k)`` (times any known shading) and the
basis ``r = B α``::

    minimise_α  Σ_k ‖y_pk − A_k B α‖²  +  λ αᵀ P α

with the spectral regulariser P of :mod:`calibration.prior` (default ``smoothness``:
P = (D B)ᵀ(D B), D the second-difference operator of paper eq. 8; or the ``training`` shape
prior). λ is *relative*:
``λ = smoothness · tr(Σ_k (A_k B)ᵀ A_k B) / tr((D B)ᵀ D B)`` (every regulariser is expressed in
the smoothness's units), so the same ``smoothness`` works whatever the units of the light and
the exposure. Without per-pixel weights the normal equations are solved once for every pixel;
with per-pixel shading or missing (NaN) values each pixel gets its own small N_b × N_b system,
solved in batches.
Every estimate is physically valid: with ``bounds`` (default ``(0, 1)``) the same quadratic is
minimised subject to ``0 ≤ B α ≤ 1`` at every wavelength (:mod:`calibration.bounds`) wherever its
unconstrained minimiser leaves them.
This is the paper's "MVS + per-pixel estimation" baseline and the optimiser's initial guess.
"""

from __future__ import annotations

import numpy as np

from calibration.basis import SpectralBasis
from calibration.bounds import bounded_quadratic
from calibration.prior import (
    Regulariser,
    SpectralRegulariser,
    smoothness_gram,
    spectral_regulariser,
)
from core.errors import RigError

DEFAULT_SMOOTHNESS = 0.1
"""Relative weight; robust with ~1 % camera noise (see calibration.selection for tuning)."""
BATCH = 65536
Bounds = tuple[float, float] | None
REFLECTANCE_BOUNDS: Bounds = (0.0, 1.0)


def response_matrices(camera: np.ndarray, spds: list[np.ndarray] | np.ndarray) -> np.ndarray:
    """``A_k = Cᵀ diag(L_k)`` for every SPD: camera sensitivity (N_λ, 3) and K light SPDs
    (K, N_λ) -> (K, 3, N_λ). Multiplying a reflectance (N_λ,) by ``A_k`` gives the RGB of a
    unit-shading, unshadowed point under light k (the forward model's response)."""
    c = np.asarray(camera, dtype=float)
    lights = np.atleast_2d(np.asarray(spds, dtype=float))
    if c.ndim != 2 or c.shape[1] != 3 or lights.shape[1] != c.shape[0]:
        raise RigError(
            f"camera {c.shape} and light SPDs {lights.shape} are not on the same grid",
            "resample both onto the same spectral grid (calibration.spectra.resample): "
            "(N_λ, 3) and (K, N_λ)",
        )
    return np.einsum("ln,kl->knl", c, lights)


def stacked_responses(resp: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The responses (K, 3, N_λ) on basis weights, the K RGB rows stacked: ``(3K, N_b)``, so
    that ``stacked_responses(resp, B) @ α`` is the K RGB triples of ``B α`` at unit shading."""
    return (resp @ B).reshape(-1, B.shape[1])


def _check(rgb: np.ndarray, resp: np.ndarray, basis: SpectralBasis) -> None:
    if resp.ndim != 3 or resp.shape[1] != 3 or resp.shape[2] != basis.B.shape[0]:
        raise RigError(
            f"response matrices have shape {resp.shape}, expected (K, 3, {basis.B.shape[0]})",
            "build them with calibration.estimation.response_matrices on the basis' grid",
        )
    if rgb.ndim != 3 or rgb.shape[1:] != resp.shape[:2]:
        raise RigError(
            f"RGB observations have shape {rgb.shape}, expected (P, {resp.shape[0]}, 3)",
            "give one RGB triple per pixel and illumination",
        )


def normal_equations(
    resp: np.ndarray,
    basis: SpectralBasis,
    smoothness: float = DEFAULT_SMOOTHNESS,
    regulariser: SpectralRegulariser | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The estimator's quadratic for unit shading: ``(lhs (N_b, N_b), m (3K, N_b))``, minimised
    by ``lhs α = mᵀ y`` with y the K RGB triples stacked; ``regulariser`` (default: smoothness)
    weighted by ``smoothness`` relative to the data."""
    reg = regulariser or spectral_regulariser("smoothness", basis)
    m = stacked_responses(resp, basis.B)
    gram = m.T @ m
    lam = smoothness * np.trace(gram) / np.trace(smoothness_gram(basis.B))
    lhs = gram + lam * reg.matrix + 1e-12 * np.trace(gram) * np.eye(gram.shape[0])
    return lhs, m


def estimation_matrix(
    resp: np.ndarray, basis: SpectralBasis, smoothness: float = DEFAULT_SMOOTHNESS
) -> np.ndarray:
    """The linear (unbounded) smoothness estimator W (N_b, 3K): ``α = W y`` with y the K RGB
    triples stacked (illumination selection's noise model)."""
    lhs, m = normal_equations(resp, basis, smoothness)
    return np.linalg.solve(lhs, m.T)


def estimate_reflectance(
    rgb: np.ndarray,
    responses: np.ndarray,
    basis: SpectralBasis,
    smoothness: float = DEFAULT_SMOOTHNESS,
    *,
    fit_scale: bool = False,
    shading: np.ndarray | None = None,
    bounds: Bounds = REFLECTANCE_BOUNDS,
    regulariser: Regulariser | SpectralRegulariser = "smoothness",
) -> tuple[np.ndarray, np.ndarray]:
    """Reflectance per pixel from ``rgb`` (P, K, 3) under ``responses`` (K, 3, N_λ), the
    matrices :func:`response_matrices` builds.

    ``shading`` (P, K), optional: a per-pixel, per-illumination factor multiplying the response
    (0 = not observed). NaN entries in ``rgb`` are missing values (saturated/masked) and are
    ignored. Pixels with no usable observation get NaN. With ``fit_scale`` the overall scale is
    treated as unknown (unknown shading or exposure) and each reflectance is normalised to a
    maximum of 1 (only the lower bound applies then). ``bounds``: the
    reflectance's ``(lower, upper)`` (an infinite upper bound where the scale is unknown), or
    None for the unbounded linear estimate. ``regulariser``: what fills what the data do not
    say (:mod:`calibration.prior`). Returns ``(alpha (P, N_b), reflectance (P, N_λ))``.
    """
    y = np.asarray(rgb, dtype=float)
    resp = np.asarray(responses, dtype=float)
    _check(y, resp, basis)
    if not smoothness >= 0:
        raise RigError(
            f"smoothness {smoothness:g} is negative or NaN",
            f"use 0 (none) or a positive relative weight (default {DEFAULT_SMOOTHNESS})",
        )
    reg = (
        regulariser
        if isinstance(regulariser, SpectralRegulariser)
        else spectral_regulariser(regulariser, basis)
    )
    if fit_scale and bounds is not None:  # an unknown scale: no upper bound
        bounds = (bounds[0], np.inf)
    missing = ~np.isfinite(y)
    if shading is None and not missing.any():
        lhs, m = normal_equations(resp, basis, smoothness, reg)
        rhs = y.reshape(y.shape[0], -1) @ m
        alpha = np.linalg.solve(lhs, rhs.T).T
        if bounds is not None:
            alpha = bounded_quadratic(lhs, rhs, basis.B, *bounds, unconstrained=alpha)
    else:
        alpha = _estimate_weighted(y, resp, basis, smoothness, reg, shading, missing, bounds)
    if fit_scale:
        refl = basis.reconstruct(alpha)
        scale = np.max(refl, axis=1, keepdims=True)
        scale[~(scale > 0)] = np.nan
        alpha = alpha / scale
    return alpha, basis.reconstruct(alpha)


def _estimate_weighted(
    y: np.ndarray,
    resp: np.ndarray,
    basis: SpectralBasis,
    smoothness: float,
    reg: SpectralRegulariser,
    shading: np.ndarray | None,
    missing: np.ndarray,
    bounds: Bounds,
) -> np.ndarray:
    """Per-pixel normal equations (P small N_b × N_b systems), solved in batches."""
    p, k, _ = y.shape
    if shading is None:
        s = np.ones((p, k))
    else:
        s = np.asarray(shading, dtype=float)
        if s.shape != (p, k) or not np.all(np.isfinite(s)):
            raise RigError(
                f"shading has shape {s.shape} (or NaN), expected finite ({p}, {k})",
                "give one shading factor per pixel and illumination (0 = not observed)",
            )
    m = resp @ basis.B  # (K, 3, N_b)
    tr_smooth = np.trace(smoothness_gram(basis.B))
    nb = basis.n_components
    alpha = np.full((p, nb), np.nan)
    for start in range(0, p, BATCH):
        sl = slice(start, start + BATCH)
        weight = np.where(missing[sl], 0.0, 1.0) * s[sl][:, :, None]  # (b, K, 3)
        yy = np.where(missing[sl], 0.0, y[sl])
        gram = np.einsum("bkn,kni,knj->bij", weight**2, m, m)
        rhs = np.einsum("bkn,kni->bi", weight * yy, m)
        tr = np.trace(gram, axis1=1, axis2=2)
        ok = tr > 0
        lam = smoothness * tr / tr_smooth
        lhs = gram + lam[:, None, None] * reg.matrix + (1e-12 * tr)[:, None, None] * np.eye(nb)
        lhs[~ok] = np.eye(nb)
        sol = np.linalg.solve(lhs, rhs[..., None])[..., 0]
        if bounds is not None:
            sol = bounded_quadratic(lhs, rhs, basis.B, *bounds, unconstrained=sol)
        sol[~ok] = np.nan
        alpha[sl] = sol
    return alpha


def noise_free_estimate(
    reflectance: np.ndarray,
    responses: np.ndarray,
    basis: SpectralBasis,
    smoothness: float = DEFAULT_SMOOTHNESS,
    regulariser: Regulariser | SpectralRegulariser = "smoothness",
) -> np.ndarray:
    """The estimator's answer (P, N_λ) for reflectances (P, N_λ) seen with unit, known shading
    and no noise: the information floor of the illuminations and camera in ``responses``."""
    r = np.asarray(reflectance, dtype=float)
    rgb = np.einsum("kcl,pl->pkc", np.asarray(responses, dtype=float), r)
    return estimate_reflectance(rgb, responses, basis, smoothness, regulariser=regulariser)[1]
