"""Colour differences as the field reports them: CIEDE2000 between reflectance spectra seen
under an illuminant by the CIE 1931 2° observer.

Reflectances (…, N_λ) on a :class:`~calibration.grid.SpectralGrid` become CIE XYZ through
:func:`calibration.colorimetry.reflectance_to_xyz` (the one spectra -> XYZ path, shared with the
sRGB previews and the viewer), then CIELAB with the illuminant's perfect diffuser as white, then
ΔE00 by ``colour.delta_E(..., method="CIE 2000")``.

>>> import numpy as np
>>> grey = np.full((1, 31), 0.5)
>>> float(delta_e00(grey, grey, illuminant("D65"))[0])
0.0
>>> round(float(reflectance_to_lab(np.ones(31), illuminant("D65"))[0]), 6)
100.0
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import asdict, dataclass
from pathlib import Path

import colour
import numpy as np

from calibration.colorimetry import reflectance_to_xyz, white_xyz
from calibration.defaults import cie_illuminant
from calibration.grid import DEFAULT_GRID, SpectralGrid
from calibration.importers import read_spectrum
from calibration.spectra import resample
from calibration.store import CalibrationStore
from core.errors import RigError

DEFAULT_ILLUMINANTS = ("D65", "A")
"""The illuminants every evaluation reports: daylight and tungsten, as conservators do."""


@dataclass(frozen=True)
class Illuminant:
    """A named SPD on a grid (any scale: XYZ is normalised to the perfect diffuser)."""

    name: str
    spd: np.ndarray
    grid: SpectralGrid = DEFAULT_GRID


def illuminant(
    spec: str | Path | np.ndarray,
    grid: SpectralGrid = DEFAULT_GRID,
    store: CalibrationStore | None = None,
    name: str | None = None,
) -> Illuminant:
    """An illuminant from a CIE name (``D65``, ``A``, ``FL2`` … via colour-science), an SPD file
    (``wavelength_nm,power`` CSV or any format ``rig calibrate import`` reads), a light entry of
    ``store``, or an SPD array already on ``grid``.

    >>> illuminant("A").name
    'A'
    """
    if isinstance(spec, np.ndarray):
        spd = np.asarray(spec, dtype=float)
        label = name or "SPD"
    elif store is not None and str(spec) in store.names("light"):
        spd, label = store.light_spd(str(spec), grid), name or str(spec)
    elif Path(spec).suffix:  # a file name (CIE names have none)
        path = Path(spec)
        if not path.is_file():
            raise RigError(
                f"illuminant file {path} does not exist",
                "give a CIE name (D65, A, FL2 …) or an SPD CSV wavelength_nm,power",
            )
        sp = read_spectrum(path)
        spd = resample(sp.wavelengths_nm, sp.column(None, "light"), grid, source=str(path))
        label = name or path.stem
    else:
        spd, label = cie_illuminant(str(spec), grid), name or str(spec)
    if spd.shape != (grid.size,) or not np.all(np.isfinite(spd)) or spd.max() <= 0:
        raise RigError(
            f"illuminant {label} has shape {spd.shape} or no power; the grid needs ({grid.size},)",
            "give an SPD with positive values on the spectral grid",
        )
    return Illuminant(label, spd, grid)


def reflectance_to_lab(reflectance: np.ndarray, light: Illuminant) -> np.ndarray:
    """CIELAB (…, 3) of reflectances (…, N_λ) under ``light``; white is its perfect diffuser."""
    xyz = reflectance_to_xyz(reflectance, light.grid, light.spd)
    white = colour.XYZ_to_xy(white_xyz(light.grid, light.spd))
    return np.asarray(colour.XYZ_to_Lab(xyz, illuminant=white), dtype=float)


def delta_e00_lab(lab_a: np.ndarray, lab_b: np.ndarray) -> np.ndarray:
    """CIEDE2000 between CIELAB colours (…, 3).

    >>> round(float(delta_e00_lab(np.array([50, 2.6772, -79.7751]),
    ...                           np.array([50, 0.0, -82.7485]))), 4)
    2.0425
    """
    return np.asarray(colour.delta_E(lab_a, lab_b, method="CIE 2000"), dtype=float)


def delta_e00(estimate: np.ndarray, truth: np.ndarray, light: Illuminant) -> np.ndarray:
    """CIEDE2000 per spectrum between ``estimate`` and ``truth`` (…, N_λ) under ``light``."""
    return delta_e00_lab(reflectance_to_lab(estimate, light), reflectance_to_lab(truth, light))


@dataclass(frozen=True)
class Summary:
    """Mean, median and 90th percentile of per-vertex errors."""

    mean: float
    median: float
    p90: float

    def text(self, digits: int = 2) -> str:
        return f"{self.mean:.{digits}f} / {self.median:.{digits}f} / {self.p90:.{digits}f}"


def summarise(values: np.ndarray, mask: np.ndarray | None = None) -> Summary:
    """:class:`Summary` of the finite ``values`` where ``mask`` holds (NaN when none)."""
    v = np.asarray(values, dtype=float)
    keep = np.isfinite(v) if mask is None else np.isfinite(v) & np.asarray(mask, dtype=bool)
    if not keep.any():
        return Summary(float("nan"), float("nan"), float("nan"))
    v = v[keep]
    return Summary(float(v.mean()), float(np.median(v)), float(np.percentile(v, 90)))


@dataclass(frozen=True)
class PatchRow:
    """One patch: its label, how many vertices it holds and the ΔE00 and spectral RMSE of the
    median estimated spectrum against the median true spectrum. ``measured`` is False where too
    little of the patch was seen for its median to be a measurement (listed, but left out of
    the mean and max)."""

    patch: int
    name: str
    vertices: int
    delta_e00: float
    rmse: float
    measured: bool = True


def per_patch(
    estimate: np.ndarray,
    truth: np.ndarray,
    patch: np.ndarray,
    light: Illuminant,
    mask: np.ndarray | None = None,
    names: list[str] | None = None,
    unmeasured: Collection[int] = (),
) -> list[PatchRow]:
    """Per patch label ≥ 0 (where ``mask`` holds): ΔE00 of the patch's median spectrum; the
    labels in ``unmeasured`` are flagged as not measured.

    The median over the patch's vertices, wavelength by wavelength, is what a spectrometer
    aimed at the patch would report, robust to the few vertices on its border.
    """
    est, tru = np.asarray(estimate, dtype=float), np.asarray(truth, dtype=float)
    labels = np.asarray(patch, dtype=int)
    keep = labels >= 0
    if mask is not None:
        keep &= np.asarray(mask, dtype=bool)
    keep &= np.all(np.isfinite(est), axis=1)
    rows = []
    for label in np.unique(labels[keep]):
        sel = keep & (labels == label)
        e, t = np.median(est[sel], axis=0), np.median(tru[sel], axis=0)
        name = names[label] if names is not None and label < len(names) else str(label)
        rows.append(PatchRow(int(label), name, int(sel.sum()),
                             float(delta_e00(e, t, light)),
                             float(np.sqrt(np.mean((e - t) ** 2))),
                             bool(label not in unmeasured)))  # fmt: skip
    return rows


@dataclass(frozen=True)
class ColourReport:
    """ΔE00 under one illuminant: per vertex (mean/median/p90) and, where patches exist, per
    patch (mean and max of the measured patches' ΔE00, and the table of all)."""

    illuminant: str
    per_vertex: Summary
    patches: list[PatchRow]

    @property
    def measured(self) -> list[float]:
        """ΔE00 of the measured patches."""
        return [p.delta_e00 for p in self.patches if p.measured]

    @property
    def patch_mean(self) -> float:
        return float(np.mean(self.measured)) if self.measured else np.nan

    @property
    def patch_max(self) -> float:
        return float(np.max(self.measured)) if self.measured else np.nan

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: per-vertex summary, patch mean/max (of the measured patches, counted in
        ``patches_measured``) and the per-patch table."""
        return {
            "illuminant": self.illuminant,
            "per_vertex": asdict(self.per_vertex),
            "patch_mean": self.patch_mean if self.measured else None,
            "patch_max": self.patch_max if self.measured else None,
            "patches_measured": len(self.measured),
            "patches": [asdict(p) for p in self.patches],
        }


def colour_report(
    estimate: np.ndarray,
    truth: np.ndarray,
    light: Illuminant,
    mask: np.ndarray | None = None,
    patch: np.ndarray | None = None,
    names: list[str] | None = None,
    unmeasured: Collection[int] = (),
) -> ColourReport:
    """ΔE00 of ``estimate`` against ``truth`` (N, N_λ) under ``light`` over the vertices in
    ``mask``; per patch too when ``patch`` labels (N,) are given (-1 = no patch), the labels in
    ``unmeasured`` listed but left out of the patch mean and max."""
    de = delta_e00(estimate, truth, light)
    rows = (
        []
        if patch is None
        else per_patch(estimate, truth, patch, light, mask, names, unmeasured)
    )
    return ColourReport(light.name, summarise(de, mask), rows)
