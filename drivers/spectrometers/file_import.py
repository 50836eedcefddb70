"""Spectrometers without a Python driver (StellarNet SpectraWiz, vendor apps, CSV exports):
the person measures in the vendor software and exports a file; this reads it with
``calibration.importers`` so the rest of the tool sees an ordinary ``Spectrometer``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from calibration.importers import read_spectrum
from core.errors import RigError
from drivers.protocols import Spectrum


class FileImportSpectrometer:
    driver_name = "file-import"

    def __init__(
        self,
        fmt: str = "auto",
        column: str | None = None,
        ask: Callable[[str], str] = input,
        dark_subtracted: bool = True,
    ) -> None:
        self.fmt = fmt
        self.column = column
        self._ask = ask
        self.dark_subtracted = dark_subtracted
        self.files: list[str] = []

    def _read(self, prompt: str) -> Spectrum:
        answer = self._ask(prompt).strip().strip("'\"")
        if not answer or answer.lower() in {"q", "quit", "abort"}:
            raise RigError("spectrum import aborted", "run the calibration again when ready")
        path = Path(answer).expanduser()
        imported = read_spectrum(path, self.fmt)
        values = imported.column(self.column, "light")
        integration_ms = imported.metadata.get("integration_time_ms")
        self.files.append(str(path))
        return Spectrum(
            wavelengths_nm=np.asarray(imported.wavelengths_nm, dtype=np.float64),
            values=np.asarray(values, dtype=np.float64),
            integration_time_s=float(integration_ms) / 1e3 if integration_ms else float("nan"),
            dark_subtracted=self.dark_subtracted,
        )

    def measure_dark(self) -> Spectrum:
        spectrum = self._read(
            "Measure the dark reference in the vendor software, export it, and type the file path: "
        )
        return replace(spectrum, dark_subtracted=False)  # a dark is never dark-subtracted

    def measure(self) -> Spectrum:
        return self._read(
            "Measure the light in the vendor software, export it, and type the file path: "
        )

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "spectrometer",
            "driver": self.driver_name,
            "format": self.fmt,
            "files": self.files,
        }

    def close(self) -> None:
        return None
