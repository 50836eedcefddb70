"""PNG plots of calibration data (matplotlib, Agg backend: works without a display)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from calibration.basis import SpectralBasis
from calibration.selection import SubsetScore
from core.files import atomic_output

RGB_COLOURS = ("tab:red", "tab:green", "tab:blue")


def _save(fig: plt.Figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    try:
        with atomic_output(path) as tmp:  # a full disk leaves no truncated plot
            fig.savefig(tmp, dpi=120)
    finally:
        plt.close(fig)
    return path


def plot_spectrum(
    wavelengths: np.ndarray,
    values: np.ndarray,
    columns: Sequence[str],
    title: str,
    path: str | Path,
) -> Path:
    """One spectrum (light: one curve; camera: R, G, B curves)."""
    fig, ax = plt.subplots(figsize=(6, 3.5))
    values = np.atleast_2d(np.asarray(values).T).T
    for j, name in enumerate(columns):
        colour = RGB_COLOURS[j] if len(columns) == 3 else None
        ax.plot(wavelengths, values[:, j], label=name, color=colour)
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("relative power" if len(columns) == 1 else "sensitivity")
    ax.set_title(title, fontsize=9)
    if len(columns) > 1:
        ax.legend()
    ax.grid(alpha=0.3)
    return _save(fig, path)


def plot_basis(basis: SpectralBasis, path: str | Path) -> Path:
    """Basis functions and cumulative explained variance."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8))
    for j in range(basis.n_components):
        left.plot(basis.wavelengths_nm, basis.B[:, j], label=f"b{j + 1}")
    left.set_xlabel("wavelength (nm)")
    left.set_title("basis functions", fontsize=9)
    left.legend(fontsize=7, ncol=2)
    left.grid(alpha=0.3)
    n = min(basis.explained_variance.size, max(12, basis.n_components + 2))
    cumulative = np.cumsum(basis.explained_variance)[:n] * 100
    right.plot(np.arange(1, n + 1), cumulative, "o-")
    right.axvline(basis.n_components, color="grey", ls="--")
    right.axhline(99, color="tab:red", ls=":", label="99 %")
    right.set_xlabel("components")
    right.set_ylabel("cumulative explained variance (%)")
    right.set_title(basis.source or "reflectance set", fontsize=8)
    right.legend()
    right.grid(alpha=0.3)
    return _save(fig, path)


def plot_selection(
    scores: Sequence[SubsetScore],
    camera: np.ndarray,
    candidates: Mapping[str, np.ndarray],
    wavelengths: np.ndarray,
    path: str | Path,
    top: int = 15,
) -> Path:
    """Camera + candidate SPDs (left) and mean RMSE of the best subsets (right), as Fig. 7."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [1, 1.3]})
    for j in range(3):
        left.plot(wavelengths, camera[:, j], color=RGB_COLOURS[j], lw=2)
    shown = list(candidates)[:12]
    for name in shown:
        spd = np.asarray(candidates[name])
        left.plot(wavelengths, spd / spd.max(), ls="--", label=name)
    left.set_xlabel("wavelength (nm)")
    left.set_title("camera (solid) and illuminations (dashed, max 1)", fontsize=9)
    left.legend(fontsize=7)
    left.grid(alpha=0.3)
    best = list(scores)[:top]
    labels = [" + ".join(s.names) for s in best]
    right.barh(np.arange(len(best)), [s.mean_rmse for s in best], color="tab:blue")
    right.set_yticks(np.arange(len(best)), labels, fontsize=7)
    right.invert_yaxis()
    right.set_xlabel("mean reflectance RMSE (reference set)")
    right.set_title("illumination sets, best first", fontsize=9)
    right.grid(alpha=0.3, axis="x")
    return _save(fig, path)
