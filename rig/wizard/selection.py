"""Step 5: which subsets of the measured illuminations recover reflectance best."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from calibration import defaults
from calibration.grid import DEFAULT_GRID


def selection_report(
    spds: dict[str, np.ndarray], camera: np.ndarray, noise: float, plots: Path, console: Console
) -> None:
    """Step 5: the best subsets (up to three illuminations) by expected spectral RMSE on the
    ColorChecker, as a table and a plot."""
    from calibration.basis import default_basis
    from calibration.plots import plot_selection
    from calibration.selection import rank_illumination_sets

    _, reflectances = defaults.colorchecker_reflectances(DEFAULT_GRID)
    scores = rank_illumination_sets(
        spds,
        camera,
        reflectances,
        default_basis(DEFAULT_GRID),
        max_size=min(3, len(spds)),
        noise=noise,
    )
    table = Table(title="5/5 illumination selection (expected spectral RMSE, ColorChecker 24)")
    for column in ("illuminations", "mean RMSE", "max RMSE"):
        table.add_column(column)
    for score in scores[:5]:
        table.add_row(" + ".join(score.names), f"{score.mean_rmse:.4f}", f"{score.max_rmse:.4f}")
    console.print(table)
    path = plot_selection(
        scores,
        camera,
        spds,
        DEFAULT_GRID.wavelengths,
        plots / "illumination-selection.png",
        min(15, len(scores)),
    )
    console.print(f"plots in {path.parent}", highlight=False)
