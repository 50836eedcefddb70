"""PNG plots of a reconstruction (matplotlib, Agg): cameras with the estimated lights, spectra
at sample vertices, the cost per iteration, and sRGB preview renders."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from core.files import atomic_output
from reconstruct.model.camera import Pose


def cameras_and_lights(
    path: Path,
    poses: Sequence[Pose],
    lights: np.ndarray,
    vertices: np.ndarray,
    true_lights: np.ndarray | None = None,
) -> Path:
    fig = plt.figure(figsize=(6, 6))
    ax = fig.add_subplot(projection="3d")
    sample = vertices[:: max(1, len(vertices) // 3000)]
    ax.scatter(*sample.T, s=1, c="0.6", label="mesh")
    centres = np.stack([p.center for p in poses])
    ax.scatter(*centres.T, c="k", marker="^", label="cameras")
    for pose, c in zip(poses, centres, strict=True):
        axis = pose.R[2] * 0.05
        ax.plot(*np.stack([c, c + axis]).T, c="k", lw=0.8)
    ax.scatter(*lights.T, c="r", s=20, label="estimated lights")
    if true_lights is not None:
        ax.scatter(*true_lights.T, c="b", s=10, marker="x", label="true lights")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("Cameras and estimated light positions")
    return _save(fig, path)


def spectra(
    path: Path,
    wavelengths: np.ndarray,
    reflectance: np.ndarray,
    indices: np.ndarray,
    initial: np.ndarray | None = None,
    truth: np.ndarray | None = None,
    band: tuple[np.ndarray, np.ndarray] | None = None,
) -> Path:
    """Estimated spectra of ``indices``; ``band`` (low, high), (N, N_λ) each, adds the shaded
    95 % uncertainty band (within [0, 1]: :func:`calibration.bounds.bounded_band`)."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    colors = plt.cm.tab10(np.linspace(0, 1, 10))
    for k, i in enumerate(indices):
        col = colors[k % 10]
        ax.plot(wavelengths, reflectance[i], color=col, lw=1.8, label=f"vertex {i}")
        if band is not None and np.all(np.isfinite(band[0][i])):
            ax.fill_between(wavelengths, band[0][i], band[1][i], color=col, alpha=0.15, lw=0)
        if initial is not None:
            ax.plot(wavelengths, initial[i], color=col, lw=0.8, ls=":")
        if truth is not None:
            ax.plot(wavelengths, truth[k], color=col, lw=0.8, ls="--")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("reflectance")
    note = "solid: estimate" + (", 95 % band" if band is not None else "")
    note += ", dotted: 2-D initial" if initial is not None else ""
    note += ", dashed: truth" if truth is not None else ""
    ax.set_title(f"Spectral reflectance at sample vertices ({note})", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    return _save(fig, path)


def cost_curve(path: Path, history: list[dict[str, Any]]) -> Path:
    fig, ax = plt.subplots(figsize=(7, 4.5))
    accepted = [h for h in history if h["accepted"]]
    x = np.arange(len(accepted))
    for term in ("total", "rendering", "spectral", "photometric", "geometric"):
        y = np.array([h["terms"][term] for h in accepted])
        ax.semilogy(x, np.maximum(y, 1e-30), label=term, lw=2 if term == "total" else 1)
    stages = [f"{h['stage']} {h['outer']}" for h in accepted]
    for k in range(1, len(stages)):
        if stages[k] != stages[k - 1]:
            ax.axvline(k - 0.5, color="0.7", lw=0.8)
    ax.set_xlabel("accepted iteration (vertical lines: stage / shadow-mask update)")
    ax.set_ylabel("cost")
    ax.set_title("Joint optimisation cost per term")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    return _save(fig, path)


def image(path: Path, rgb8: np.ndarray, title: str) -> Path:
    fig, ax = plt.subplots(figsize=(rgb8.shape[1] / 100, rgb8.shape[0] / 100 + 0.3))
    ax.imshow(rgb8)
    ax.set_title(title, fontsize=9)
    ax.axis("off")
    return _save(fig, path)


def error_histogram(path: Path, errors: np.ndarray, label: str) -> Path:
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.hist(errors[np.isfinite(errors)], bins=60, color="tab:red", alpha=0.8)
    ax.set_xlabel(label)
    ax.set_ylabel("vertices")
    ax.grid(alpha=0.3)
    return _save(fig, path)


def _save(fig: Any, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    try:
        with atomic_output(path) as tmp:  # a full disk leaves no truncated plot
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return path
