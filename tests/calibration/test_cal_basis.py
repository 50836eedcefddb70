"""Uncentred PCA basis: planted rank, the paper's Munsell claim, persistence."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calibration.basis import SpectralBasis, default_basis, pca_basis
from calibration.grid import DEFAULT_GRID
from calibration.importers import read_reflectance_set
from calibration.spectra import resample
from core.errors import RigError


def test_pca_recovers_a_planted_rank() -> None:
    rng = np.random.default_rng(3)
    true_basis, _ = np.linalg.qr(rng.standard_normal((31, 4)))
    refl = rng.standard_normal((200, 4)) @ true_basis.T
    basis = pca_basis(refl, 4, "planted")
    assert basis.explained_variance[:4].sum() == pytest.approx(1.0)
    assert basis.explained_variance[4:].max() < 1e-20
    # same subspace: projector onto it reproduces the planted basis
    np.testing.assert_allclose(basis.B @ basis.B.T @ true_basis, true_basis, atol=1e-10)
    np.testing.assert_allclose(basis.B.T @ basis.B, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(basis.reconstruct(basis.project(refl)), refl, atol=1e-10)


def test_component_signs_are_deterministic() -> None:
    refl = np.abs(np.random.default_rng(4).standard_normal((50, 31)))
    a = pca_basis(refl, 3)
    b = pca_basis(-refl, 3)  # same subspace, flipped data
    np.testing.assert_allclose(a.B, b.B, atol=1e-12)


def test_munsell_eight_components_explain_99_percent(shared_data: Path) -> None:
    labels, w, values = read_reflectance_set(
        shared_data / "reflectance" / "munsell_matt_1269_380_780_5nm.csv"
    )
    assert len(labels) == 1269 and w[0] == 380 and w[-1] == 780
    refl = resample(w, values.T, DEFAULT_GRID).T
    basis = pca_basis(refl, 8, "Munsell 1269")
    share = float(np.sum(basis.explained_variance[:8]))
    assert share >= 0.99
    # and the basis reconstructs every chip closely
    err = refl - basis.reconstruct(basis.project(refl))
    rmse = np.sqrt(np.mean(err**2, axis=1))
    assert rmse.mean() < 0.01 and rmse.max() < 0.04


def test_default_basis_from_colour_science_data(tmp_path: Path) -> None:
    basis = default_basis()
    assert basis.B.shape == (31, 8)
    assert np.sum(basis.explained_variance[:8]) > 0.99
    path = basis.save(tmp_path / "b.npz")
    loaded = SpectralBasis.load(path)
    np.testing.assert_array_equal(loaded.B, basis.B)
    np.testing.assert_array_equal(loaded.wavelengths_nm, DEFAULT_GRID.wavelengths)
    assert loaded.source == basis.source and loaded.grid == DEFAULT_GRID


def test_basis_errors(tmp_path: Path) -> None:
    with pytest.raises(RigError, match="has 30 samples per row"):
        pca_basis(np.ones((10, 30)), 3, "short.csv")
    with pytest.raises(RigError, match="cannot take 12 components from 10"):
        pca_basis(np.ones((10, 31)), 12)
    with pytest.raises(RigError, match="NaN"):
        pca_basis(np.full((10, 31), np.nan), 3)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(RigError, match="cannot read spectral basis"):
        SpectralBasis.load(bad)
