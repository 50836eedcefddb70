"""Spectrometers: seabreeze logic against a fake Spectrometer object (counts grow with
integration time and clip at full scale), and vendor-file import through
calibration.importers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import RigError
from drivers.protocols import Spectrometer
from drivers.spectrometers.file_import import FileImportSpectrometer
from drivers.spectrometers.seabreeze_spectrometer import SeabreezeSpectrometer


class FakeOceanSpectrometer:
    """Mimics seabreeze.spectrometers.Spectrometer: 1000-count offset, signal ∝ time, and the
    first scan after a change of integration time still uses the old time."""

    model = "USB2000+"
    serial_number = "USB2+F01234"
    max_intensity = 65535.0
    integration_time_micros_limits = (1000, 10_000_000)

    def __init__(self) -> None:
        self._wl = np.linspace(350, 1000, 651)
        self.light_on = True
        self.time_us = 0
        self.running_us = 0  # the free-running scan under way, started before any change
        self.reads = 0
        self.rng = np.random.default_rng(1)

    def wavelengths(self) -> np.ndarray:
        return self._wl

    def integration_time_micros(self, us: int) -> None:
        self.time_us = us

    def intensities(self) -> np.ndarray:
        self.reads += 1
        used_us, self.running_us = self.running_us, self.time_us
        rate = 4e5 * np.exp(-0.5 * ((self._wl - 550) / 40) ** 2)  # counts per second
        signal = rate * used_us * 1e-6 if self.light_on else 0
        counts = 1000 + signal + self.rng.normal(0, 2, self._wl.shape)
        return np.minimum(counts, self.max_intensity)

    def close(self) -> None: ...


def test_auto_range_dark_and_measurement() -> None:
    device = FakeOceanSpectrometer()
    spec = SeabreezeSpectrometer(device, integration_time_s=1.0, averages=4)
    assert isinstance(spec, Spectrometer)
    assert spec.measure().saturated  # 1 s clips at full scale
    t = spec.auto_range()
    assert 0.05 < t < 0.2  # peak 1000 + 4e5 t ≈ 0.75 * 65535
    device.light_on = False
    dark = spec.measure_dark()
    assert not dark.dark_subtracted and dark.integration_time_s == t
    device.light_on = True
    reads = device.reads
    reading = spec.measure()
    assert device.reads - reads == 4  # averaged
    assert reading.dark_subtracted and not reading.saturated
    peak = reading.values[np.argmin(abs(device.wavelengths() - 550))]
    assert peak == pytest.approx(4e5 * t, rel=0.01)
    assert np.max(reading.values + 1000) / 65535 == pytest.approx(0.75, abs=0.05)


def test_dark_from_another_integration_time_is_refused() -> None:
    device = FakeOceanSpectrometer()
    spec = SeabreezeSpectrometer(device, integration_time_s=0.01)
    spec.measure_dark()
    spec.set_integration_time(0.02)
    with pytest.raises(RigError, match="take the dark again"):
        spec.measure()


def test_integration_time_is_clamped_to_the_device_limits() -> None:
    spec = SeabreezeSpectrometer(FakeOceanSpectrometer(), integration_time_s=1e-6)
    assert spec.integration_time_s == 0.001
    assert spec.describe()["serial"] == "USB2+F01234"


def test_file_import_reads_a_vendor_csv_export(tmp_path: Path) -> None:
    export = tmp_path / "led1.csv"
    wavelengths = np.arange(380, 781, 1.0)
    power = np.exp(-0.5 * ((wavelengths - 450) / 10) ** 2)
    export.write_text(
        "wavelength_nm,power\n"
        + "".join(f"{w:g},{p:.6f}\n" for w, p in zip(wavelengths, power, strict=True))
    )
    answers = iter([str(export), "q"])
    spec = FileImportSpectrometer(fmt="csv", ask=lambda prompt: next(answers))
    reading = spec.measure()
    assert reading.wavelengths_nm[0] == 380 and reading.values.max() == pytest.approx(1.0)
    assert np.isnan(reading.integration_time_s)
    with pytest.raises(RigError, match="aborted"):
        spec.measure()
    assert spec.describe()["files"] == [str(export)]


def test_file_import_missing_file_names_it(tmp_path: Path) -> None:
    spec = FileImportSpectrometer(ask=lambda prompt: str(tmp_path / "nope.IRR"))
    with pytest.raises(RigError, match="nope.IRR"):
        spec.measure()
