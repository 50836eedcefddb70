"""Spectral reflectance basis B (N_λ, N_b): uncentred PCA of a reflectance set (paper eq. 7).

Uncentred because the model is ``r = B α`` with no mean term: the first component carries the
average spectrum and the explained "variance" is the share of total energy Σ r², which is what
bounds the reconstruction error of ``r ≈ B Bᵀ r``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibration.defaults import training_reflectances
from calibration.grid import DEFAULT_GRID, SpectralGrid
from core.errors import RigError
from core.files import atomic_output


@dataclass
class SpectralBasis:
    """Orthonormal basis ``B`` (N_λ, N_b) with the share of energy each component explains."""

    B: np.ndarray
    wavelengths_nm: np.ndarray
    explained_variance: np.ndarray
    source: str = ""

    @property
    def n_components(self) -> int:
        return int(self.B.shape[1])

    @property
    def grid(self) -> SpectralGrid:
        return SpectralGrid.from_wavelengths(self.wavelengths_nm)

    def project(self, reflectances: np.ndarray) -> np.ndarray:
        """Least-squares weights α (…, N_b) of reflectances (…, N_λ) (B is orthonormal)."""
        return np.asarray(reflectances) @ self.B

    def reconstruct(self, alpha: np.ndarray) -> np.ndarray:
        """Reflectances (…, N_λ) from weights (…, N_b)."""
        return np.asarray(alpha) @ self.B.T

    def save(self, path: str | Path) -> Path:
        """Write ``.npz`` (B, wavelengths_nm, explained_variance, source)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_output(path) as tmp, open(tmp, "wb") as handle:
            np.savez(
                handle,
                B=self.B,
                wavelengths_nm=self.wavelengths_nm,
                explained_variance=self.explained_variance,
                source=np.array(self.source),
            )
        return path

    @classmethod
    def load(cls, path: str | Path) -> SpectralBasis:
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                basis = cls(
                    B=np.asarray(data["B"], dtype=float),
                    wavelengths_nm=np.asarray(data["wavelengths_nm"], dtype=float),
                    explained_variance=np.asarray(data["explained_variance"], dtype=float),
                    source=str(data["source"]),
                )
        except (OSError, KeyError, ValueError) as error:
            raise RigError(
                f"cannot read spectral basis {path}: {error}",
                "write one with `rig calibrate basis --out FILE.npz`",
            ) from error
        if basis.B.ndim != 2 or basis.B.shape[0] != basis.wavelengths_nm.size:
            raise RigError(f"spectral basis {path} is malformed", "rebuild it with rig calibrate")
        return basis


def pca_basis(
    reflectances: np.ndarray,
    n_components: int = 8,
    source: str = "",
    *,
    grid: SpectralGrid = DEFAULT_GRID,
) -> SpectralBasis:
    """Uncentred PCA (SVD) of ``reflectances`` (M, N_λ) sampled on ``grid``.

    ``explained_variance`` has one entry per singular value (all of them, so cumulative shares
    beyond ``n_components`` can be reported); component signs are fixed so each component's
    largest-magnitude entry is positive (deterministic output).
    """
    r = np.asarray(reflectances, dtype=float)
    name = source or "reflectance set"
    if r.ndim != 2:
        raise RigError(f"{name} must be a table (M, N_λ)", "give one row per sample")
    m, n = r.shape
    if n != grid.size:
        raise RigError(
            f"{name} has {n} samples per row, the grid has {grid.size}",
            "resample the reflectances onto the grid first (calibration.spectra.resample)",
        )
    if not np.all(np.isfinite(r)):
        raise RigError(f"{name} contains NaN or inf", "fix or drop those rows")
    if not 1 <= n_components <= min(m, n):
        raise RigError(
            f"cannot take {n_components} components from {m} reflectances × {n} wavelengths",
            f"use between 1 and {min(m, n)} components",
        )
    _, s, vt = np.linalg.svd(r, full_matrices=False)
    energy = s**2
    b = vt[:n_components].T.copy()
    b *= np.sign(b[np.argmax(np.abs(b), axis=0), np.arange(n_components)])
    return SpectralBasis(b, grid.wavelengths, energy / energy.sum(), source)


def default_basis(grid: SpectralGrid = DEFAULT_GRID, n_components: int = 8) -> SpectralBasis:
    """Basis of the reflectances shipped with colour-science (190 rawtoaces patches + CC24)."""
    return pca_basis(
        training_reflectances(grid),
        n_components,
        source="colour-science rawtoaces 190 training patches + ColorChecker 24 (BabelColor)",
        grid=grid,
    )
