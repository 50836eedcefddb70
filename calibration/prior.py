"""What a reflectance is expected to look like before the camera says anything: the spectral
regulariser ``‖R (α − μ)‖²`` of every estimate, and the statistics of real surfaces' basis weights.

Two cameras' RGB under two lamps give six numbers for eight basis weights: the rest of the
spectrum is the regulariser's. Two regularisers are registered:

* ``training`` (the default): a Gaussian prior on α learnt from real reflectances
  (:func:`weight_statistics` of rawtoaces' 190 training patches; the ColorChecker, which every
  benchmark scene is painted with, is left out), ``R = Σ^-½``, ``μ`` their mean weights;
* ``smoothness``: the paper's eq. 14, the second difference of ``B α`` over wavelength
  (``R`` its R factor, ``μ = 0``).

Both are expressed in the smoothness's units (their matrices ``RᵀR`` scaled to a fixed share
of its trace), so the relative weights of the 2-D estimator and the γ1 of the joint cost mean
the same strength whichever is used. Measured on the information floor (bench/README.md): the
training prior holds more of the spectrum's shape than smoothness does where no channel sees it.

>>> from calibration.basis import default_basis
>>> reg = spectral_regulariser("training", default_basis())
>>> reg.matrix.shape, reg.mean.shape
((8, 8), (8,))
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
# The training prior's trace as a share of the smoothness's: the relative weight at which, with
# the 2-D estimator's default smoothness, it reaches the lowest ΔE00 on held-out Munsell chips
# under the benchmark's measured lamps and cameras with 1 % noise (bench/README.md).
TRAINING_STRENGTH = 0.1


@dataclass(frozen=True)
class SpectralRegulariser:
    """``‖R (α − μ)‖²`` over basis weights α: ``matrix = RᵀR`` (N_b, N_b), ``mean = μ``."""

    name: str
    matrix: np.ndarray
    mean: np.ndarray

    def scale_free(self) -> SpectralRegulariser:
        """The same shape penalty about 0: for reflectances known only up to a factor, which
        an absolute mean would pull on."""
        return SpectralRegulariser(self.name, self.matrix, np.zeros_like(self.mean))

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
        return SpectralRegulariser(name, smooth, np.zeros(basis.n_components))
    if name == "training":
        stats = weight_statistics(basis, prior_reflectances(basis))
        precision = np.linalg.pinv(stats.cov, hermitian=True)
        scale = TRAINING_STRENGTH * np.trace(smooth) / np.trace(precision)
        return SpectralRegulariser(name, scale * precision, stats.mean)
    raise RigError(
        f"spectral regulariser {name!r} is unknown",
        f"use one of {', '.join(REGULARISERS)}",
    )
