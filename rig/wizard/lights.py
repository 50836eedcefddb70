"""Steps 1 and 2: a dark reference and each illumination's SPD (measured, or imported)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from calibration.grid import DEFAULT_GRID
from calibration.spectra import resample
from core.errors import RigError
from drivers.protocols import Spectrometer, Spectrum
from drivers.spectrometers.autorange import auto_range_spectrometer
from rig.capture.devices import RigDevices, device_errors
from rig.profile import Profile
from rig.wizard.common import Ask, set_light, step, today


@dataclass
class MeasuredLight:
    """One illumination's SPD at its measured sampling, before and after the scale."""

    name: str  # illumination name in the profile
    entry: str  # calibration store entry name
    wavelengths: np.ndarray
    values: np.ndarray  # relative (counts/s or the imported file's units) until scaled
    provenance: dict[str, Any]
    scale: float | None = None

    def on_grid(self) -> np.ndarray:
        return resample(self.wavelengths, self.values, DEFAULT_GRID, source=self.name)


def parse_imports(items: list[str], profile: Profile) -> dict[str, Path]:
    """``--import ILLUMINATION=FILE`` flags by illumination."""
    out = {}
    for item in items:
        name, sep, file = item.partition("=")
        if not sep or name not in profile.illuminations:
            raise RigError(
                f"--import {item!r} does not name an illumination of {profile.source}",
                f"write ILLUMINATION=FILE with one of {', '.join(profile.illuminations)}",
            )
        out[name] = Path(file)
    return out


def _entry_name(profile: Profile, illumination: str) -> str:
    if profile.calibration is not None:
        return profile.calibration.lights.get(illumination, illumination)
    return illumination


def measure_lights(
    profile: Profile,
    devices: RigDevices,
    imports: dict[str, Path],
    ask: Ask | None,
    console: Console,
) -> list[MeasuredLight]:
    """Steps 1 and 2: per illumination, an integration time that fills the detector, a dark
    reference at that time with the light off, then the dark-subtracted SPD (or an import)."""
    spectrometer = devices.spectrometer
    if spectrometer is not None:
        step(
            ask,
            console,
            "1/5 dark references are taken with the light off before each "
            "measurement: shade the spectrometer's input from room light",
        )
    out: list[MeasuredLight] = []
    for name in profile.plan.illuminations:
        entry = _entry_name(profile, name)
        if name in imports:
            out.append(_import_light(name, entry, imports[name]))
            console.print(f"2/5 {name}: imported from {imports[name]}", highlight=False)
            continue
        if spectrometer is None:
            raise RigError(
                f"{profile.source} has no spectrometer to measure '{name}'",
                f"add devices.spectrometer or pass --import {name}=FILE",
            )
        step(ask, console, f"2/5 {name}: point the spectrometer at the light")
        where = ("spectrometer", devices.names.get("spectrometer", "?"), f"measure {name}")
        with device_errors(*where):
            set_light(devices, profile, name)
            auto_range_spectrometer(spectrometer)
            set_light(devices, profile, None)
            spectrometer.measure_dark()
            set_light(devices, profile, name)
            spectrum = spectrometer.measure()
        set_light(devices, profile, None)
        if spectrum.saturated:
            raise RigError(
                f"spectrometer saturates on '{name}'",
                "shorten its integration time or move it away from the light",
            )
        out.append(_measured(name, entry, spectrum, spectrometer, devices))
        console.print(
            f"2/5 {name}: measured at {1000 * spectrum.integration_time_s:.4g} ms", highlight=False
        )
    return out


def _measured(
    name: str, entry: str, spectrum: Spectrum, spectrometer: Spectrometer, devices: RigDevices
) -> MeasuredLight:
    """The SPD in counts/s (noise below zero clipped), with its provenance."""
    values = np.clip(np.asarray(spectrum.values, float) / spectrum.integration_time_s, 0.0, None)
    describe = spectrometer.describe()
    light = devices.light.describe() if devices.light is not None else {}
    prov = {
        "source": "measured by rig calibrate wizard",
        "device": light.get("model"),
        "serial": light.get("serial"),
        "date": today(),
        "instrument": f"{describe.get('model', '?')} ({describe.get('serial', '?')})",
        "integration_time_ms": 1000 * spectrum.integration_time_s,
        "notes": f"counts/s, dark-subtracted={spectrum.dark_subtracted}",
    }
    return MeasuredLight(name, entry, np.asarray(spectrum.wavelengths_nm, float), values, prov)


def _import_light(name: str, entry: str, path: Path) -> MeasuredLight:
    from calibration.importers import read_spectrum

    spectrum = read_spectrum(path)
    values = spectrum.column(None, "light")
    prov = {
        **dict(spectrum.metadata),
        "source": f"imported from {path} ({spectrum.format})",
        "date": today(),
    }
    return MeasuredLight(name, entry, spectrum.wavelengths_nm, np.asarray(values, float), prov)


def plot_light(light: MeasuredLight, values: np.ndarray, plots: Path, version: int) -> Path:
    """The stored SPD as a PNG in ``plots``."""
    from calibration.plots import plot_spectrum

    slug = "".join(c if c.isalnum() or c in "-_." else "-" for c in light.entry)
    unit = "scaled to the forward model's units" if light.scale else "relative"
    return plot_spectrum(
        light.wavelengths,
        values[:, None],
        ["power"],
        f"{light.name} ({light.entry} v{version}, {unit})",
        plots / f"spd-{slug}.v{version}.png",
    )
