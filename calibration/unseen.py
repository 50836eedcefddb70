"""The part of a reflectance the camera barely sees, left to the spectral regulariser.

K illuminations × RGB are 3K numbers for N_b basis weights. Along a right singular vector of the
stacked responses ``Q = C_kᵀ L_k B`` whose singular value is a small share of the largest, a
whole unit of weight moves the rendered colours less than the images' noise and the model's
error move them, and a fit follows those errors there, amplified by the inverse of that share.
With two illuminations and eight weights two directions are not seen at all and the regulariser
alone sets them; with three, the eighth is seen, but barely, and its fitted value is noise.

:func:`complete_unseen` sets each estimate's weakly seen and unseen part as the regulariser
would set an unseen one: the smallest ``αᵀ P α`` within the bounds, what the responses see well
held (truncated-SVD regularisation of the weak directions).

>>> from calibration.basis import default_basis
>>> from calibration.estimation import stacked_responses
>>> from calibration.prior import smoothness_gram
>>> basis = default_basis(); B = basis.B; P = smoothness_gram(B)
>>> responses = np.abs(np.random.default_rng(0).normal(size=(2, 3, B.shape[0])))  # two lamps
>>> smooth = basis.project(np.linspace(0.2, 0.6, B.shape[0]))
>>> rough = smooth + 0.2 * weak_directions(B, responses, 0.003)[:, 0]  # a wave nothing sees
>>> done = complete_unseen(rough[None], B, responses, P, share=0.003)[0]
>>> Q = stacked_responses(responses, B)
>>> bool(np.allclose(Q @ done, Q @ rough))  # the colours are as fitted
True
>>> bool(done @ P @ done < rough @ P @ rough)  # the spectrum is smoother
True
"""

from __future__ import annotations

import numpy as np

from calibration.bounds import bounded_quadratic
from calibration.estimation import stacked_responses

# How hard the strongly seen part is held, relative to the regulariser's scale, in the rows
# whose completion meets a bound (the others are completed exactly): far beyond any curvature
# the regulariser has, so what the camera sees well stays as it was fitted.
HOLD = 1e6
# A direction seen at this share of the strongest or less is round-off: not seen at all.
UNSEEN_SHARE = 1e-9


def _directions(B: np.ndarray, responses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each basis-weight direction (rows of an orthonormal (N_b, N_b)) with how strongly the
    stacked responses see it, relative to the strongest (N_b,; 0 for the unseen ones)."""
    rows = stacked_responses(np.asarray(responses, dtype=float), B)
    _, sv, vt = np.linalg.svd(rows, full_matrices=True)
    strength = np.zeros(B.shape[1])
    strength[: sv.size] = sv / sv[0]
    return strength, vt


def seen_strengths(B: np.ndarray, responses: np.ndarray) -> np.ndarray:
    """How strongly the responses (K, 3, N_λ) see each basis-weight direction, relative to the
    strongest, in decreasing order (N_b,).

    >>> B = np.eye(3); Q = np.array([[[1.0, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 0.0]]])
    >>> seen_strengths(B, Q).tolist()
    [1.0, 0.0001, 0.0]
    """
    return _directions(B, responses)[0]


def weak_directions(B: np.ndarray, responses: np.ndarray, share: float) -> np.ndarray:
    """Orthonormal basis-weight directions (N_b, m) that the stacked responses (K, 3, N_λ) see
    at less than ``share`` of their strongest direction, the unseen ones included.

    >>> B = np.eye(3); Q = np.array([[[1.0, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 0.0]]])
    >>> weak_directions(B, Q, 0.003).shape
    (3, 2)
    """
    strength, vt = _directions(B, responses)
    weak: np.ndarray = vt[strength < share].T
    return weak


def complete_unseen(
    alpha: np.ndarray,
    B: np.ndarray,
    responses: np.ndarray,
    regulariser: np.ndarray,
    share: float,
    lower: float = 0.0,
    upper: float = 1.0,
) -> np.ndarray:
    """``alpha`` (P, N_b) with its part along :func:`weak_directions` re-solved for the smallest
    ``αᵀ regulariser α`` with ``lower ≤ B α ≤ upper``; the rest of each row held. Rows of a
    valid ``alpha`` stay valid; ``share`` 0 returns ``alpha`` unchanged."""
    alpha = np.asarray(alpha, dtype=float)
    weak = weak_directions(B, responses, share)
    if weak.shape[1] == 0 or alpha.size == 0:
        return alpha.copy()
    held = alpha - (alpha @ weak) @ weak.T
    # unconstrained: z = -(Wᵀ P W)⁺ Wᵀ P s per row (the regulariser may be flat along some W)
    reduced = np.linalg.pinv(weak.T @ regulariser @ weak, hermitian=True)
    free = held - (held @ regulariser @ weak @ reduced) @ weak.T
    strong = np.eye(B.shape[1]) - weak @ weak.T
    scale = max(float(np.trace(regulariser)), 1e-12)
    stiffness = HOLD * scale * strong
    # a trace of ridge where the regulariser is flat along a weak direction (a grey or a ramp)
    hessian = regulariser + stiffness + 1e-9 * scale * weak @ weak.T
    return bounded_quadratic(
        hessian, alpha @ stiffness, B, lower, upper, start=alpha, unconstrained=free
    )
