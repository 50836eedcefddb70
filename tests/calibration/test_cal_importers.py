"""Importers on sample files of every supported format, and malformed inputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cal_samples import WAVELENGTHS, led, oceanview_text, spectrawiz_text

from calibration.grid import DEFAULT_GRID
from calibration.importers import (
    detect_format,
    read_colour_dataset,
    read_reflectance_set,
    read_spectrum,
)
from calibration.spectra import resample
from core.errors import RigError

GRID_W = DEFAULT_GRID.wavelengths


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_oceanview_export(tmp_path: Path) -> None:
    path = write(tmp_path, "LED1.txt", oceanview_text(WAVELENGTHS, led(WAVELENGTHS)))
    assert detect_format(path) == "oceanview"
    spec = read_spectrum(path)
    assert spec.format == "oceanview" and spec.values.shape == (WAVELENGTHS.size, 1)
    assert spec.metadata["serial"] == "FLMS01234"
    assert spec.metadata["integration_time_ms"] == pytest.approx(100.0)
    assert spec.metadata["operator"] == "lab"
    on_grid = resample(spec.wavelengths_nm, spec.column(None, "light"))
    # dense data are averaged over a 10 nm band around each grid wavelength
    band = np.array([led(np.linspace(x - 5, x + 5, 1001)).mean() for x in GRID_W])
    np.testing.assert_allclose(on_grid, band, atol=1e-3)


def test_oceanview_decimal_comma_and_spectrasuite(tmp_path: Path) -> None:
    text = oceanview_text(WAVELENGTHS, led(WAVELENGTHS), decimal_comma=True)
    spec = read_spectrum(write(tmp_path, "comma.txt", text))
    np.testing.assert_allclose(spec.wavelengths_nm, WAVELENGTHS)
    assert spec.metadata["integration_time_ms"] == pytest.approx(100.0)
    suite = (
        "SpectraSuite Data File\n++++\nIntegration Time (usec): 100000 (QEB1523)\n"
        "Spectrometers: QEB1523\n>>>>>Begin Processed Spectral Data<<<<<\n"
        + "\n".join(f"{w:.2f}\t{v:.4E}" for w, v in zip(WAVELENGTHS, led(WAVELENGTHS), strict=True))
        + "\n>>>>>End Processed Spectral Data<<<<<\n"
    )
    spec = read_spectrum(write(tmp_path, "x.SSIrrad", suite))
    assert spec.metadata["integration_time_ms"] == pytest.approx(100.0)
    assert spec.metadata["serial"] == "QEB1523"


@pytest.mark.parametrize("suffix", [".IRR", ".SSM", ".ABS", ".TRM"])
def test_spectrawiz_files(tmp_path: Path, suffix: str) -> None:
    w = np.arange(300.0, 850.5, 0.5)
    path = write(tmp_path, f"LED2{suffix}", spectrawiz_text(w, led(w)))
    spec = read_spectrum(path)
    assert spec.format == "spectrawiz"
    assert spec.metadata["integration_time_ms"] == pytest.approx(150.0)
    assert spec.columns == [
        {".IRR": "irradiance", ".SSM": "scope", ".ABS": "absorbance", ".TRM": "transmission"}[
            suffix
        ]
    ]
    np.testing.assert_allclose(spec.values[:, 0], led(w), rtol=1e-5)


def test_spectrawiz_detected_by_content(tmp_path: Path) -> None:
    w = np.arange(350.0, 800.0, 1.0)
    path = write(tmp_path, "export.txt", spectrawiz_text(w, led(w)))
    assert detect_format(path) == "spectrawiz"


def test_generic_tables(tmp_path: Path) -> None:
    w = np.arange(380, 781, 5)
    rgb = np.stack([led(w), 0.5 * led(w), 0.25 * led(w)], axis=1)
    rows = [f"{a},{r:.6f},{g:.6f},{b:.6f}" for a, (r, g, b) in zip(w, rgb, strict=True)]
    camera = read_spectrum(write(tmp_path, "cam.csv", "wavelength_nm,R,G,B\n" + "\n".join(rows)))
    np.testing.assert_allclose(camera.column(None, "camera"), rgb, atol=1e-6)
    # header with other names and column order, tab separated, comment line
    text = "# measured 2025-01-01\nnm\tblue\tgreen\tred\n" + "\n".join(
        f"{a}\t{b:.6f}\t{g:.6f}\t{r:.6f}" for a, (r, g, b) in zip(w, rgb, strict=True)
    )
    camera2 = read_spectrum(write(tmp_path, "cam.tsv", text))
    np.testing.assert_allclose(camera2.column(None, "camera"), rgb, atol=1e-6)
    # no header, whitespace separated, one column
    light = read_spectrum(
        write(tmp_path, "l.dat", "\n".join(f"{a} {v:.6f}" for a, v in zip(w, led(w), strict=True)))
    )
    assert light.columns == ["power"]
    # semicolon + decimal comma, several columns, pick one
    text = "wl;LED1;LED2\n" + "\n".join(
        f"{a};{v:.5f};{2 * v:.5f}".replace(".", ",") for a, v in zip(w, led(w), strict=True)
    )
    multi = read_spectrum(write(tmp_path, "m.csv", text))
    np.testing.assert_allclose(multi.column("led2", "light"), 2 * led(w), atol=1e-4)


def test_colour_datasets() -> None:
    fl2 = read_spectrum("colour:FL2")
    assert fl2.values.shape[1] == 1 and "SDS_ILLUMINANTS" in fl2.metadata["source"]
    nikon = read_colour_dataset("Nikon 5100 (NPL)")
    assert nikon.values.shape[1] == 3
    canon = read_colour_dataset("canon eos 5d mark ii")
    assert "rawtoaces" in canon.metadata["source"]


def test_reflectance_set_both_layouts(tmp_path: Path) -> None:
    w = np.arange(400, 701, 10)
    rows = np.stack([np.linspace(0.1, 0.9, w.size), np.full(w.size, 0.5)])
    by_row = (
        "label,"
        + ",".join(str(x) for x in w)
        + "\n"
        + "\n".join(f"chip{i}," + ",".join(f"{v:.4f}" for v in r) for i, r in enumerate(rows))
    )
    labels, wl, values = read_reflectance_set(write(tmp_path, "rows.csv", by_row))
    assert labels == ["chip0", "chip1"] and values.shape == (2, 31)
    by_col = "wavelength_nm,a,b\n" + "\n".join(
        f"{x},{a:.4f},{b:.4f}" for x, a, b in zip(w, rows[0], rows[1], strict=True)
    )
    labels2, wl2, values2 = read_reflectance_set(write(tmp_path, "cols.csv", by_col))
    assert labels2 == ["a", "b"]
    np.testing.assert_allclose(values2, values, atol=1e-4)
    with pytest.raises(RigError, match="looks like percent"):
        read_reflectance_set(write(tmp_path, "pct.csv", by_col.replace(",0.", ",9")))


TABLE_OK = "wavelength_nm,power\n" + "\n".join(f"{w},{1.0}" for w in range(380, 781, 10))

MALFORMED: list[tuple[str, str, str, str]] = [
    ("empty.csv", "", "auto", "is empty"),
    ("header_only.csv", "wavelength_nm,power\n", "csv", "no spectral data"),
    ("text.csv", TABLE_OK.replace("500,1.0", "500,abc"), "csv", r"text.csv:14: not a number"),
    ("ragged.csv", TABLE_OK.replace("500,1.0", "500,1.0,2.0"), "csv", "3 columns where"),
    ("dup.csv", TABLE_OK.replace("510,1.0", "500,1.0"), "csv", "duplicate wavelength 500"),
    ("desc.csv", TABLE_OK.replace("510,1.0", "490,1.0"), "csv", "not increasing"),
    ("nan.csv", TABLE_OK.replace("500,1.0", "500,nan"), "csv", "NaN or inf at 500"),
    ("onecol.csv", "\n".join(str(w) for w in range(400, 701, 10)), "csv", "only one column"),
    ("header.csv", "wavelength_nm,a,b\n400,1\n500,1\n", "csv", "header has 3 names"),
    (
        "ov_nobegin.txt",
        "Spectrometer: X\nIntegration Time (sec): 0.1\n400\t1\n",
        "oceanview",
        "no '>>>>>Begin",
    ),
    (
        "ov_empty.txt",
        ">>>>>Begin Spectral Data<<<<<\n>>>>>End Spectral Data<<<<<\n",
        "oceanview",
        "no spectral data",
    ),
    (
        "ov_bad.txt",
        ">>>>>Begin Spectral Data<<<<<\n400\t1\n410\tx\n",
        "oceanview",
        r":3: not a number",
    ),
    ("sw_bad.IRR", '"SpectraWiz"\n400 1\n410\n', "spectrawiz", r":3: expected 'wavelength value'"),
    ("sw_empty.SSM", "", "spectrawiz", "is empty"),
    ("few.csv", "400,1\n500,1\n600,1\n", "csv", "only 3 samples"),
]


@pytest.mark.parametrize(("name", "text", "fmt", "message"), MALFORMED)
def test_malformed_files_give_clear_errors(
    tmp_path: Path, name: str, text: str, fmt: str, message: str
) -> None:
    path = write(tmp_path, name, text)
    with pytest.raises(RigError, match=message) as info:
        read_spectrum(path, fmt)
    assert str(path) in str(info.value) and info.value.fix


def test_other_bad_inputs(tmp_path: Path) -> None:
    with pytest.raises(RigError, match="does not exist"):
        read_spectrum(tmp_path / "missing.csv")
    binary = tmp_path / "spectrum.spc"
    binary.write_bytes(b"\x00\x01\x02binary")
    with pytest.raises(RigError, match="binary file"):
        read_spectrum(binary)
    with pytest.raises(RigError, match="unknown spectrum format"):
        read_spectrum(binary, "xlsx")
    with pytest.raises(RigError, match="no colour-science dataset named 'nope'"):
        read_spectrum("colour:nope")
    two = read_spectrum(
        write(tmp_path, "two.csv", "wl,a,b\n" + "\n".join(f"{w},1,2" for w in range(400, 701, 10)))
    )
    with pytest.raises(RigError, match="pick one with --column"):
        two.column(None, "light")
    with pytest.raises(RigError, match="no column 'c'"):
        two.column("c", "light")
    with pytest.raises(RigError, match="needs 3 columns"):
        two.column(None, "camera")
