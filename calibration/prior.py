"""What a reflectance is expected to look like before the camera says anything: the spectral
regulariser ``αᵀ P α`` of every estimate, and the statistics of real surfaces' basis weights.

Two lamps × RGB give six numbers for eight basis weights: the rest of the spectrum is the
regulariser's. Two regularisers are registered:

* ``smoothness`` (the default): the paper's eq. 14, the second difference of ``B α`` over
  wavelength, which leaves a flat spectrum of any level alone;
* ``training``: the Gaussian prior of real reflectances' basis weights
  (:func:`weight_statistics` of rawtoaces' 190 training patches; the ColorChecker, which every
  benchmark scene is painted with, is left out) — its precision Σ⁻¹ with the direction of their
  mean weights μ taken out, ``P = Σ⁻¹ − Σ⁻¹μ μᵀΣ⁻¹ / μᵀΣ⁻¹μ``: it judges a spectrum's *shape*
  against real surfaces' at whatever brightness (``P μ = 0``), so it never pulls on the
  brightness, which the light's distance, the shading and so the geometry trade against.

Both are expressed in the smoothness's units (the training precision scaled to a fixed share of
the smoothness's trace), so the relative weights of the 2-D estimator and the γ1 of the joint
cost mean the same strength whichever is used. The training prior lowers the 2-D estimator's
information floor by a quarter on chips it never saw, but has not yet lowered the joint solve's
colour error on the external scenes (bench/README.md, ``spectral_prior``): it is an option, not
the default.

>>> from calibration.basis import default_basis
>>> reg = spectral_regulariser("training", default_basis())
>>> reg.matrix.shape
(8, 8)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from calibration.basis import SpectralBasis
from calibration.spectra import second_difference_matrix
from core.errors import RigError

Regulariser = Literal["training", "smoothness"]
REGULARISERS: tuple[Regulariser, ...] = ("training", "smoothness")
# The training precision's trace as a share of the smoothness's (before its mean direction is
# taken out): read off held-out Munsell chips under the benchmark's measured lamps and cameras
# with 1 % noise (bench/README.md, spectral_prior).
TRAINING_STRENGTH = 0.1


@dataclass(frozen=True)
class SpectralRegulariser:
    """``αᵀ P α`` over basis weights α, ``matrix = P`` (N_b, N_b), positive semi-definite."""

    name: str
    matrix: np.ndarray

    @property
    def factor(self) -> np.ndarray:
        """Square R with ``RᵀR = matrix`` (the residual rows of the joint cost)."""
        w, v = np.linalg.eigh(self.matrix)
        return (v * np.sqrt(np.clip(w, 0.0, None))).T


@dataclass(frozen=True)
class WeightStatistics:
    """Real surfaces in the basis: their weights' mean μ (N_b,) and covariance Σ, and their
    mean squared residual outside the basis span per wavelength (N_λ,)."""

    mean: np.ndarray
    cov: np.ndarray
    truncation_var: np.ndarray


def weight_statistics(basis: SpectralBasis, reflectances: np.ndarray) -> WeightStatistics:
    """:class:`WeightStatistics` of ``reflectances`` (M, N_λ) on ``basis``."""
    weights = basis.project(reflectances)
    residual = reflectances - basis.reconstruct(weights)
    return WeightStatistics(
        mean=np.mean(weights, axis=0),
        cov=np.cov(weights, rowvar=False),
        truncation_var=np.mean(residual**2, axis=0),
    )


def smoothness_gram(B: np.ndarray) -> np.ndarray:
    """(D B)ᵀ (D B) of a basis matrix B (N_λ, N_b): the paper's spectral smoothness (eq. 14)
    in basis weights."""
    db = second_difference_matrix(B.shape[0]) @ B
    return db.T @ db


def prior_reflectances(basis: SpectralBasis) -> np.ndarray:
    """The training prior's reflectances: rawtoaces' 190 patches (colour-science) on the
    basis' grid, without the ColorChecker."""
    from calibration.defaults import rawtoaces_reflectances

    return rawtoaces_reflectances(basis.grid)


def spectral_regulariser(name: Regulariser, basis: SpectralBasis) -> SpectralRegulariser:
    """The registered regulariser ``name`` on ``basis`` (module docstring)."""
    smooth = smoothness_gram(basis.B)
    if name == "smoothness":
        return SpectralRegulariser(name, smooth)
    if name == "training":
        stats = weight_statistics(basis, prior_reflectances(basis))
        precision = np.linalg.pinv(stats.cov, hermitian=True)
        precision *= TRAINING_STRENGTH * np.trace(smooth) / np.trace(precision)
        towards_mean = precision @ stats.mean
        shape = precision - np.outer(towards_mean, towards_mean) / (stats.mean @ towards_mean)
        return SpectralRegulariser(name, (shape + shape.T) / 2)
    raise RigError(
        f"spectral regulariser {name!r} is unknown",
        f"use one of {', '.join(REGULARISERS)}",
    )
