"""Choosing the illuminations to capture with (paper, Sec. 4.1 and Fig. 7 right).

Every subset of 1..K candidate SPDs is scored by the mean spectral RMSE of the reference
reflectances (ColorChecker 24 by default) recovered with :mod:`calibration.estimation` from
simulated camera RGB.

Noise model (stated, deterministic): each illumination is exposed so a perfect white reflector
reads 1.0 in its brightest channel, and every channel value carries additive, independent
Gaussian noise of standard deviation ``noise`` (relative to that white level, e.g. 0.01 = 1 %).
The estimator is linear (``r̂ = W y``), so the *expected* squared error of each patch is exact:
``‖W A r − r‖² + noise² ‖W‖²_F`` — no random draws; the RMSE reported is the square root of
its mean over wavelengths, averaged over patches. Unless a smoothness is given, each subset is
scored with the smoothness weight (from :data:`SMOOTHNESS_GRID`) that is best for it, so sets
are compared at their own best regularisation, as a user would tune it.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from calibration.basis import SpectralBasis
from calibration.estimation import DEFAULT_SMOOTHNESS, estimation_matrix, response_matrices
from core.errors import RigError

MAX_SUBSETS = 20000
SMOOTHNESS_GRID = tuple(float(x) for x in np.logspace(-4, 1, 11))


@dataclass(frozen=True)
class SubsetScore:
    """One candidate subset and its expected reconstruction error."""

    names: tuple[str, ...]
    mean_rmse: float
    max_rmse: float
    per_patch_rmse: np.ndarray
    smoothness: float


def normalised_responses(
    camera: np.ndarray, spds: list[np.ndarray], names: list[str] | None = None
) -> np.ndarray:
    """``Cᵀ diag(L_k)`` scaled so a perfect white reads 1.0 in its brightest channel."""
    resp = response_matrices(camera, spds)
    white = resp.sum(axis=2).max(axis=1)
    bad = [i for i, w in enumerate(white) if not (np.isfinite(w) and w > 0)]
    if bad:
        name = f"illumination {names[bad[0]]!r}" if names else "a candidate illumination"
        what = "no" if np.isfinite(white[bad[0]]) else "an overflowing"
        raise RigError(
            f"{name} gives {what} camera signal on 400–700 nm",
            "check its SPD (values, unit, wavelength range) and import it again",
        )
    return resp / white[:, None, None]


def expected_rmse(
    resp: np.ndarray,
    reflectances: np.ndarray,
    basis: SpectralBasis,
    noise: float,
    smoothness: float = DEFAULT_SMOOTHNESS,
) -> np.ndarray:
    """Expected per-reflectance RMSE (M,) under the module's noise model."""
    w = basis.B @ estimation_matrix(resp, basis, smoothness)  # (N_λ, 3K)
    a = resp.reshape(-1, resp.shape[2])  # (3K, N_λ)
    bias = reflectances @ (w @ a).T - reflectances
    n_lambda = reflectances.shape[1]
    mse = (np.sum(bias**2, axis=1) + noise**2 * float(np.sum(w**2))) / n_lambda
    return np.sqrt(mse)


def rank_illumination_sets(
    candidates: Mapping[str, np.ndarray],
    camera: np.ndarray,
    reflectances: np.ndarray,
    basis: SpectralBasis,
    *,
    max_size: int = 3,
    noise: float = 0.01,
    smoothness: float | None = None,
) -> list[SubsetScore]:
    """Score every subset of 1..``max_size`` candidates; best (lowest mean RMSE) first."""
    names = list(candidates)
    if not names:
        raise RigError("no candidate illuminations", "add light SPDs to the store or name them")
    if max_size < 1:
        raise RigError(f"--max-size {max_size} must be at least 1", "use 1 or more")
    if noise < 0:
        raise RigError(f"noise {noise} is negative", "give the noise as a fraction, e.g. 0.01")
    if smoothness is not None and not smoothness >= 0:
        raise RigError(f"--smoothness {smoothness:g} is negative", "use 0 or more, or leave it out")
    max_size = min(max_size, len(names))
    total = sum(math.comb(len(names), k) for k in range(1, max_size + 1))
    if total > MAX_SUBSETS:
        raise RigError(
            f"{len(names)} candidates give {total} subsets of size ≤ {max_size}",
            f"lower --max-size or the number of candidates (limit {MAX_SUBSETS})",
        )
    resp = normalised_responses(camera, [np.asarray(candidates[n]) for n in names], names)
    weights = SMOOTHNESS_GRID if smoothness is None else (smoothness,)
    scores = []
    for k in range(1, max_size + 1):
        for combo in itertools.combinations(range(len(names)), k):
            try:
                tries = [
                    (expected_rmse(resp[list(combo)], reflectances, basis, noise, sm), sm)
                    for sm in weights
                ]
            except np.linalg.LinAlgError as error:
                raise RigError(
                    f"the illuminations {' + '.join(names[i] for i in combo)} give no usable "
                    f"estimate ({error})",
                    "check their SPDs, or give a positive --smoothness",
                ) from error
            rmse, best = min(tries, key=lambda t: float(t[0].mean()))
            scores.append(
                SubsetScore(
                    tuple(names[i] for i in combo),
                    float(rmse.mean()),
                    float(rmse.max()),
                    rmse,
                    best,
                )
            )
    return sorted(scores, key=lambda s: (s.mean_rmse, len(s.names)))


def channel_mixtures(
    channels: Mapping[str, np.ndarray], levels: tuple[float, ...] = (0.0, 1.0)
) -> dict[str, np.ndarray]:
    """Every mix of the light's channels at the given levels (all-off excluded).

    Names read like ``r+g`` (levels 1) or ``r0.5+c`` for other levels.
    """
    keys = list(channels)
    out: dict[str, np.ndarray] = {}
    for combo in itertools.product(levels, repeat=len(keys)):
        if not any(combo):
            continue
        parts = [k if lv == 1 else f"{k}{lv:g}" for k, lv in zip(keys, combo, strict=True) if lv]
        out["+".join(parts)] = sum(
            (lv * np.asarray(channels[k]) for k, lv in zip(keys, combo, strict=True) if lv),
            np.zeros_like(np.asarray(channels[keys[0]], dtype=float)),
        )
    return out
