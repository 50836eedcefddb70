"""Ocean Insight (Ocean Optics) spectrometers through python-seabreeze (optional extra).

Workflow: ``auto_range()`` with the light on picks an integration time that puts the peak
near ``target_fraction`` of full scale; ``measure_dark()`` with the light off records the
dark reference at that time; ``measure()`` averages scans, subtracts the dark and flags
saturation. A dark taken at another integration time is never silently reused.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from core.errors import MissingDependencyError, RigError
from drivers.protocols import Spectrum
from drivers.spectrometers.autorange import auto_range

log = logging.getLogger(__name__)

SETTLED = 0.05  # peak within this relative distance of the target: auto-ranging stops


def open_seabreeze(serial: str | None = None, backend: str | None = None) -> Any:
    try:
        import seabreeze

        if backend:
            seabreeze.use(backend)
        from seabreeze.spectrometers import Spectrometer, list_devices
    except ImportError as error:
        raise MissingDependencyError(
            "seabreeze", "seabreeze", "needed for Ocean spectrometers"
        ) from error
    devices = list_devices()
    if not devices:
        raise RigError(
            "no Ocean/seabreeze spectrometer is connected",
            "plug it in; on Linux run `seabreeze_os_setup` once to install its udev rules",
        )
    try:
        if serial:
            return Spectrometer.from_serial_number(serial)
        return Spectrometer(devices[0])
    except Exception as error:  # seabreeze raises its own SeaBreezeError types per backend
        raise RigError(
            f"cannot open spectrometer {serial or devices[0]}: {error}",
            "close OceanView or other programs using it, or check the serial in the profile",
        ) from error


class SeabreezeSpectrometer:
    driver_name = "seabreeze"

    def __init__(
        self,
        device: Any,
        integration_time_s: float = 0.1,
        averages: int = 3,
        target_fraction: float = 0.75,
        saturation_fraction: float = 0.98,
        max_integration_s: float = 10.0,
    ) -> None:
        self.device = device
        low_us, high_us = device.integration_time_micros_limits
        self.min_s = low_us * 1e-6
        self.max_s = min(high_us * 1e-6, max_integration_s)
        if averages < 1:
            raise RigError(f"spectrometer averages = {averages}", "use 1 or more")
        self.averages = averages
        self.target_fraction = target_fraction
        self.saturation_fraction = saturation_fraction
        self.full_scale = float(device.max_intensity)
        self.wavelengths = np.asarray(device.wavelengths(), dtype=np.float64)
        self.integration_time_s = 0.0
        self.set_integration_time(integration_time_s)
        self.dark: Spectrum | None = None

    def set_integration_time(self, seconds: float) -> None:
        """Set the time and drop one scan: a free-running Ocean spectrometer returns the
        spectrum already under way, integrated with the old time (python-seabreeze #110)."""
        seconds = float(np.clip(seconds, self.min_s, self.max_s))
        if seconds == self.integration_time_s:
            return
        self.device.integration_time_micros(int(round(seconds * 1e6)))
        self.integration_time_s = seconds
        self.device.intensities()

    def _scan(self, count: int) -> np.ndarray:
        scans = [np.asarray(self.device.intensities(), dtype=np.float64) for _ in range(count)]
        return np.mean(scans, axis=0)

    def _saturated(self, raw: np.ndarray) -> bool:
        return bool(np.max(raw) >= self.saturation_fraction * self.full_scale)

    def auto_range(self, max_steps: int = 8) -> float:
        """Integration time putting the peak near ``target_fraction`` of full scale."""

        def read() -> tuple[float, float, bool]:
            peak = float(np.max(self._scan(1)))
            return self.integration_time_s, peak, self._saturated(np.array([peak]))

        auto_range(
            read,
            self.set_integration_time,
            self.full_scale,
            target_fill=self.target_fraction,
            tolerance=SETTLED,
            min_s=self.min_s,
            max_s=self.max_s,
            max_steps=max_steps,
        )
        if self.dark is not None and self.dark.integration_time_s != self.integration_time_s:
            self.dark = None  # it was for another integration time
        log.info("spectrometer integration time %.4f s", self.integration_time_s)
        return self.integration_time_s

    def measure_dark(self) -> Spectrum:
        raw = self._scan(self.averages)
        self.dark = Spectrum(
            self.wavelengths, raw, self.integration_time_s, False, self._saturated(raw)
        )
        return self.dark

    def measure(self) -> Spectrum:
        raw = self._scan(self.averages)
        saturated = self._saturated(raw)
        if saturated:
            log.warning("spectrometer saturated at %.4f s: run auto-range", self.integration_time_s)
        if self.dark is None:
            return Spectrum(self.wavelengths, raw, self.integration_time_s, False, saturated)
        if self.dark.integration_time_s != self.integration_time_s:
            raise RigError(
                f"the dark reference was taken at {self.dark.integration_time_s:g} s but the "
                f"reading uses {self.integration_time_s:g} s",
                "take the dark again (light off) after changing the integration time",
            )
        return Spectrum(
            self.wavelengths, raw - self.dark.values, self.integration_time_s, True, saturated
        )

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "spectrometer",
            "driver": self.driver_name,
            "model": str(getattr(self.device, "model", "?")),
            "serial": str(getattr(self.device, "serial_number", "?")),
            "integration_time_s": self.integration_time_s,
            "averages": self.averages,
        }

    def close(self) -> None:
        self.device.close()
