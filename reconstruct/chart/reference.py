"""Reference reflectances of a chart's patches: the ColorChecker Classic 24 the project knows
(BabelColor average, colour-science), or a CSV of any target."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibration.defaults import colorchecker_reflectances
from calibration.grid import DEFAULT_GRID, SpectralGrid
from calibration.spectra import resample
from core.errors import RigError
from reconstruct.chart.detect import Layout

CSV_FORM = "a CSV `wavelength_nm,<patch 1>,<patch 2>,…` (reflectance 0–1, one column per patch)"


@dataclass(frozen=True)
class Reference:
    """Patch names and reflectances (N, N_λ) in chart order, and where they came from."""

    names: list[str]
    reflectance: np.ndarray
    source: str


def default_reference(chart: Layout, grid: SpectralGrid = DEFAULT_GRID) -> Reference:
    """The built-in reference of ``chart`` (the ColorChecker Classic 24)."""
    names, refl = colorchecker_reflectances(grid)
    if len(names) != chart.size:
        raise RigError(
            f"no built-in reference for chart layout {chart.name}", f"give --reference {CSV_FORM}"
        )
    return Reference(names, refl, "ColorChecker 24 (BabelColor average, colour-science)")


def read_reference(path: Path, chart: Layout, grid: SpectralGrid = DEFAULT_GRID) -> Reference:
    """Reference reflectances from ``path`` (:data:`CSV_FORM`), one column per patch in chart
    order (rows from the top-left patch), resampled onto ``grid``."""
    path = Path(path)
    try:
        header = path.read_text().splitlines()[0].split(",")
        table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, IndexError, ValueError) as exc:
        raise RigError(f"cannot read reference {path}: {exc}", f"give {CSV_FORM}") from exc
    if table.shape[1] != chart.size + 1 or len(header) != chart.size + 1:
        raise RigError(
            f"reference {path} has {table.shape[1] - 1} patch columns, the {chart.name} chart "
            f"has {chart.size}",
            f"give {CSV_FORM}",
        )
    values = table[:, 1:]
    if not np.all(np.isfinite(values)) or values.min() < 0 or values.max() > 1.5:
        raise RigError(
            f"reference {path} holds values outside 0–1.5 (percent?)",
            "give reflectances as fractions (0–1)",
        )
    refl = resample(table[:, 0], values, grid, source=str(path)).T
    return Reference([h.strip() for h in header[1:]], refl, str(path))
