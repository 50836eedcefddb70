"""The chart check's files: ``chart_check.json`` (everything), ``chart_check.csv`` (one row per
patch) and ``chart_check.png`` (estimated against reference spectra, one panel per patch laid
out as on the chart)."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from calibration.grid import DEFAULT_GRID
from core.files import write_bytes_atomically
from core.lock import output_lock
from reconstruct.chart.check import CHECK_CHART, ChartCheck
from reconstruct.chart.detect import Layout

JSON_FILE = "chart_check.json"
CSV_FILE = "chart_check.csv"
PLOT_FILE = "chart_check.png"


def rows(check: ChartCheck) -> list[dict[str, Any]]:
    """One mapping per patch: index, name, ΔE00 per illuminant, spectral RMSE."""
    out = []
    for k, name in enumerate(check.reference.names):
        row: dict[str, Any] = {"patch": k + 1, "name": name}
        for light, de in check.delta_e.items():
            row[f"delta_e00_{light}"] = round(float(de[k]), 4)
        row["rmse"] = round(float(check.rmse[k]), 5)
        out.append(row)
    return out


def _listed(values: np.ndarray) -> list[Any]:
    """Nested lists with None where a value is NaN (a saturated patch): valid JSON."""
    out = np.asarray(values, dtype=object)
    out[~np.isfinite(np.asarray(values, dtype=float))] = None
    return list(out.tolist())


def as_dict(check: ChartCheck) -> dict[str, Any]:
    """JSON-ready: summary, per-patch rows, spectra, and per view the shading plane and the
    patches' linear RGB and spread under each illumination."""
    return {
        "reference": check.reference.source,
        "illuminations": check.illuminations,
        "shading": "one plane over the chart per view, fitted to the ratio of estimated to "
        "reference mean reflectance (module reconstruct.chart.check)",
        "summary": check.summary(),
        "patches": rows(check),
        "wavelengths_nm": DEFAULT_GRID.wavelengths.tolist(),
        "estimate": np.round(check.estimate, 5).tolist(),
        "reference_reflectance": np.round(check.reference.reflectance, 5).tolist(),
        "views": [
            {
                "view": v.view,
                "shading_plane": v.shading_plane.tolist(),
                "corners_px": next(iter(v.patches.values())).corners.tolist(),
                "rgb": {n: _listed(p.rgb) for n, p in v.patches.items()},
                "spread": {n: _listed(p.spread) for n, p in v.patches.items()},
                "pixels": {n: p.pixels.tolist() for n, p in v.patches.items()},
            }
            for v in check.views
        ],
    }


def plot(check: ChartCheck, chart: Layout, path: Path) -> Path:
    """Estimated (per view, thin; median, thick) against reference spectra, one panel per
    patch laid out as on the chart."""
    wl = DEFAULT_GRID.wavelengths
    fig, axes = plt.subplots(
        chart.rows, chart.cols, figsize=(2.2 * chart.cols, 1.9 * chart.rows),
        sharex=True, sharey=True, squeeze=False,
    )  # fmt: skip
    first = next(iter(check.delta_e))
    for k, ax in enumerate(axes.ravel()):
        for v in check.views:
            ax.plot(wl, v.estimate[k], color="tab:blue", lw=0.5, alpha=0.4)
        ax.plot(wl, check.reference.reflectance[k], color="k", lw=1.5, label="reference")
        ax.plot(wl, check.estimate[k], color="tab:red", lw=1.5, label="estimate")
        ax.set_title(
            f"{check.reference.names[k]}\nΔE00 {first} {check.delta_e[first][k]:.2f}", fontsize=7
        )
        ax.set_ylim(0.0, 1.1)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=6)
    axes[0, 0].legend(fontsize=6)
    fig.supxlabel("wavelength (nm)", fontsize=8)
    fig.supylabel("reflectance", fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write(check: ChartCheck, chart: Layout, out_dir: Path) -> list[Path]:
    """Write the three files into ``out_dir``, holding the lock of the session it is in."""
    with output_lock(out_dir, CHECK_CHART):
        return _write(check, chart, out_dir)


def _write(check: ChartCheck, chart: Layout, out_dir: Path) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    table = rows(check)
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(table[0]))
    writer.writeheader()
    writer.writerows(table)
    write_bytes_atomically(out_dir / CSV_FILE, text.getvalue().encode())
    write_bytes_atomically(out_dir / JSON_FILE, json.dumps(as_dict(check), indent=1).encode())
    return [out_dir / JSON_FILE, out_dir / CSV_FILE, plot(check, chart, out_dir / PLOT_FILE)]
