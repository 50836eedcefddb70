"""Simulated spectrometer: reads whatever SPD the rig's light emits right now, on its own
dense wavelength axis (like a CCD spectrometer's pixels), with a dark pedestal, seeded noise and
saturation, so calibration code runs the same path as with an Ocean Insight / StellarNet unit."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from calibration.grid import DEFAULT_GRID, SpectralGrid
from core.errors import RigError
from drivers.protocols import Spectrum


class SimSpectrometer:
    """Counts = SPD (interpolated onto 380–780 nm, 0.5 nm pixels) × counts_per_unit ×
    integration time + dark pedestal + noise, saturating at ``max_counts``."""

    def __init__(
        self,
        source: Callable[[], np.ndarray],
        seed: int = 0,
        grid: SpectralGrid = DEFAULT_GRID,
        integration_time_s: float = 0.1,
        counts_per_unit: float = 1.0e7,
        max_counts: float = 65535.0,
        serial: str = "SIM-SPEC-0001",
    ) -> None:
        self.source = source
        self.grid = grid
        self.wavelengths = np.arange(380.0, 780.0 + 1e-9, 0.5)
        self.integration_time_s = float(integration_time_s)
        self.counts_per_unit = counts_per_unit
        self.max_counts = max_counts
        self.serial = serial
        self._rng = np.random.default_rng([seed, 3])
        self._pedestal = 1000.0 + 20.0 * np.sin(self.wavelengths / 7.0)  # fixed-pattern dark
        self._dark: np.ndarray | None = None

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "spectrometer",
            "model": "spectral-rig simulated spectrometer",
            "serial": self.serial,
            "transport": "sim",
            "range_nm": [float(self.wavelengths[0]), float(self.wavelengths[-1])],
        }

    def close(self) -> None:
        self._dark = None

    def set_integration_time(self, seconds: float) -> None:
        if not seconds > 0:
            raise RigError(f"integration time {seconds} s", "use a positive integration time")
        self.integration_time_s = float(seconds)
        self._dark = None  # a dark is only valid for its integration time

    def _read(self, spd: np.ndarray) -> np.ndarray:
        signal = np.interp(self.wavelengths, self.grid.wavelengths, spd, left=0.0, right=0.0)
        counts = signal * self.counts_per_unit * self.integration_time_s + self._pedestal
        counts = self._rng.poisson(np.maximum(counts, 0.0)) + self._rng.normal(0, 3.0, counts.size)
        return np.minimum(counts, self.max_counts)

    def measure_dark(self) -> Spectrum:
        dark = self._read(np.zeros(self.grid.size))
        self._dark = dark
        return Spectrum(self.wavelengths.copy(), dark, self.integration_time_s, False)

    def measure(self) -> Spectrum:
        raw = self._read(np.asarray(self.source(), dtype=float))
        saturated = bool(np.any(raw >= self.max_counts))
        if self._dark is None:
            return Spectrum(self.wavelengths.copy(), raw, self.integration_time_s, False, saturated)
        return Spectrum(
            self.wavelengths.copy(), raw - self._dark, self.integration_time_s, True, saturated
        )
