"""Writers of sample spectrometer exports (OceanView, SpectraWiz) used by the calibration tests."""

from __future__ import annotations

import numpy as np

WAVELENGTHS = np.round(np.arange(340.0, 820.0, 0.5), 3)


def led(w: np.ndarray | float) -> np.ndarray:
    """A smooth test SPD (blue pump + phosphor) with a known shape."""
    return 0.8 * np.exp(-0.5 * ((w - 450) / 10) ** 2) + 0.5 * np.exp(-0.5 * ((w - 570) / 50) ** 2)


def oceanview_text(w: np.ndarray, v: np.ndarray, decimal_comma: bool = False) -> str:
    head = [
        "Data from LED1_AbsoluteIrradiance__0__10-11-12-130.txt Node",
        "",
        "Date: Thu Jun 19 19:20:35 CEST 2025",
        "User: lab",
        "Spectrometer: FLMS01234",
        "Trigger mode: 0",
        "Integration Time (sec): 1.000000E-1",
        "Scans to average: 5",
        "Nonlinearity correction enabled: true",
        "Boxcar width: 0",
        "XAxis mode: Wavelengths",
        f"Number of Pixels in Spectrum: {w.size}",
        ">>>>>Begin Spectral Data<<<<<",
    ]
    rows = [f"{a:.3f}\t{b:.6f}" for a, b in zip(w, v, strict=True)]
    if decimal_comma:
        rows = [r.replace(".", ",") for r in rows]
        head[6] = "Integration Time (sec): 1,000000E-1"
    return "\n".join(head + rows + [">>>>>End Spectral Data<<<<<", ""])


def spectrawiz_text(w: np.ndarray, v: np.ndarray) -> str:
    head = [
        '"SpectraWiz Ver5.33 (c) StellarNet Inc"',
        '"Irradiance Watts/m^2"',
        '"Int. Time = 150 ms   Avg = 3   Smooth = 0"',
        '"BLUE-Wave VIS-25 SN 21020001"',
    ]
    rows = [f"{a:.1f}  {b:.6E}" for a, b in zip(w, v, strict=True)]
    return "\n".join(head + rows + [""])
