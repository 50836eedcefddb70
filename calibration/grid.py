"""The spectral grid every spectrum in spectral-rig lives on: 400–700 nm in 10 nm steps
(docs/architecture.md, Spectral grid)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.errors import RigError


@dataclass(frozen=True)
class SpectralGrid:
    """Evenly spaced wavelengths ``start, start+step, ..., stop`` in nanometres (inclusive)."""

    start_nm: float = 400.0
    stop_nm: float = 700.0
    step_nm: float = 10.0

    def __post_init__(self) -> None:
        if not (self.step_nm > 0 and self.stop_nm > self.start_nm):
            raise RigError(
                f"invalid spectral grid {self.start_nm}–{self.stop_nm} nm step {self.step_nm}",
                "use start < stop and a positive step (default 400–700 nm, 10 nm)",
            )
        span = (self.stop_nm - self.start_nm) / self.step_nm
        if abs(span - round(span)) > 1e-9:
            raise RigError(
                f"spectral grid {self.start_nm}–{self.stop_nm} nm is not a whole number of "
                f"{self.step_nm} nm steps",
                "choose a step that divides stop - start",
            )

    @property
    def wavelengths(self) -> np.ndarray:
        """Wavelengths in nm, shape (N_λ,)."""
        n = int(round((self.stop_nm - self.start_nm) / self.step_nm)) + 1
        return self.start_nm + self.step_nm * np.arange(n, dtype=float)

    @property
    def size(self) -> int:
        return int(self.wavelengths.size)

    @classmethod
    def from_wavelengths(cls, wavelengths: np.ndarray) -> SpectralGrid:
        """The grid of an evenly spaced wavelength array (e.g. read back from a file)."""
        w = np.asarray(wavelengths, dtype=float)
        if w.ndim != 1 or w.size < 2 or not np.allclose(np.diff(w), w[1] - w[0]):
            raise RigError(
                "wavelengths are not evenly spaced", "resample the spectrum onto a regular grid"
            )
        return cls(float(w[0]), float(w[-1]), float(w[1] - w[0]))


DEFAULT_GRID = SpectralGrid()
