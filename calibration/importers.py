"""Readers for spectrometer exports and spectral tables.

Supported (``fmt``):

* ``csv`` — generic CSV/TSV/semicolon/whitespace tables: first column wavelength (nm), one or
  more value columns, optional header row, ``#`` comment lines; a decimal comma is accepted when
  the delimiter is not a comma.
* ``oceanview`` — Ocean Insight OceanView / SpectraSuite text exports (``key: value`` header,
  data between ``>>>>>Begin ... Spectral Data<<<<<`` and the end marker, tab separated,
  decimal point or comma).
* ``spectrawiz`` — StellarNet SpectraWiz text files (``.IRR`` irradiance, ``.SSM`` scope,
  ``.ABS`` absorbance, ``.TRM``): quoted header lines, then ``wavelength value`` rows.
* ``colour:NAME`` (not a file) — a colour-science dataset: CIE illuminants, light sources,
  camera sensitivities and the built-in cameras.

Every reader returns an :class:`ImportedSpectrum` with what the file says about the instrument
(for provenance) and raises :class:`RigError` naming the file and line on malformed input.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import colour
import numpy as np

from calibration import defaults
from calibration.spectra import validate_spectrum
from core.errors import RigError

FORMATS = ("auto", "csv", "oceanview", "spectrawiz")
SPECTRAWIZ_SUFFIXES = {
    ".irr": "irradiance",
    ".ssm": "scope",
    ".abs": "absorbance",
    ".trm": "transmission",
}
_BEGIN = re.compile(r">{3,}\s*Begin.*Spectral Data\s*<{3,}", re.IGNORECASE)
_END = re.compile(r">{3,}\s*End.*Spectral Data\s*<{3,}", re.IGNORECASE)


@dataclass
class ImportedSpectrum:
    """A spectrum read from a file or dataset, at its own sampling."""

    wavelengths_nm: np.ndarray
    values: np.ndarray  # (M, k)
    columns: list[str]
    format: str
    source: str
    metadata: dict[str, Any] = field(default_factory=dict)

    def column(self, name: str | None, kind: str) -> np.ndarray:
        """Values for a store entry: (M,) power for a light, (M, 3) RGB for a camera."""
        lower = [c.lower() for c in self.columns]
        if kind == "camera":
            if name is not None:
                raise RigError(
                    f"--column is for lights; {self.source} is a camera table", "omit --column"
                )
            for names in (("r", "g", "b"), ("red", "green", "blue")):
                if all(n in lower for n in names):
                    return self.values[:, [lower.index(n) for n in names]]
            if self.values.shape[1] == 3:
                return self.values
            raise RigError(
                f"{self.source}: a camera sensitivity needs 3 columns (R, G, B), found "
                f"{self.values.shape[1]} ({', '.join(self.columns)})",
                "export wavelength_nm,R,G,B or name the columns R, G, B in the header",
            )
        if name is not None:
            if name.lower() not in lower:
                raise RigError(
                    f"{self.source} has no column {name!r}",
                    f"choose one of {', '.join(self.columns)}",
                )
            return self.values[:, lower.index(name.lower())]
        if self.values.shape[1] != 1:
            raise RigError(
                f"{self.source} has {self.values.shape[1]} value columns "
                f"({', '.join(self.columns)})",
                "pick one with --column NAME",
            )
        return self.values[:, 0]


def _number(text: str, decimal_comma: bool) -> float:
    text = text.strip().strip('"')
    if decimal_comma:
        text = text.replace(",", ".")
    return float(text)


def _read_text(path: Path) -> list[str]:
    try:
        raw = path.read_bytes()
    except OSError as error:
        raise RigError(
            f"cannot read {path}: {error.strerror or error}", "check the path"
        ) from error
    if b"\x00" in raw[:4096]:
        raise RigError(
            f"{path} is a binary file",
            "export the spectrum as text (CSV or the software's text format)",
        )
    try:
        return raw.decode("utf-8-sig").splitlines()
    except UnicodeDecodeError:  # older vendor software writes Latin-1 (e.g. "µs")
        return raw.decode("latin-1").splitlines()


def _finish(
    path: Path,
    fmt: str,
    w: list[float],
    rows: list[list[float]],
    columns: list[str],
    meta: dict[str, Any],
) -> ImportedSpectrum:
    if not w:
        raise RigError(
            f"{path}: no spectral data found ({fmt})",
            "check that the file holds wavelength/value rows",
        )
    wl, values = validate_spectrum(w, rows, source=str(path), nonnegative=False)
    return ImportedSpectrum(wl, values, columns, fmt, str(path), meta)


def read_table(path: str | Path) -> ImportedSpectrum:
    """Generic CSV/TSV table: wavelength then one or more value columns, header optional."""
    path = Path(path)
    lines = [
        (i + 1, ln)
        for i, ln in enumerate(_read_text(path))
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if not lines:
        raise RigError(f"{path} is empty", "export at least a wavelength and a value column")
    sample = lines[min(1, len(lines) - 1)][1]
    delimiter: str | None
    if "\t" in sample:
        delimiter = "\t"
    elif ";" in sample:
        delimiter = ";"
    elif "," in sample:
        delimiter = ","
    else:
        delimiter = None  # whitespace
    decimal_comma = delimiter in ("\t", ";", None) and bool(re.search(r"\d,\d", sample))

    def split(line: str) -> list[str]:
        return [c.strip() for c in (line.split(delimiter) if delimiter else line.split())]

    first = split(lines[0][1])
    try:
        _number(first[0], decimal_comma)
        header = None
    except ValueError:
        header = [c.strip('"') for c in first]
        lines = lines[1:]
    w: list[float] = []
    rows: list[list[float]] = []
    width = None
    for lineno, line in lines:
        cells = split(line)
        if width is None:
            width = len(cells)
            if width < 2:
                raise RigError(
                    f"{path}:{lineno}: only one column",
                    "give wavelength and at least one value per row",
                )
        if len(cells) != width:
            raise RigError(
                f"{path}:{lineno}: {len(cells)} columns where earlier rows have {width}",
                "every row needs the same columns",
            )
        try:
            nums = [_number(c, decimal_comma) for c in cells]
        except ValueError as error:
            raise RigError(
                f"{path}:{lineno}: not a number ({error})", "fix or remove that row"
            ) from error
        w.append(nums[0])
        rows.append(nums[1:])
    k = (width or 2) - 1
    if header is not None and len(header) != k + 1:
        raise RigError(
            f"{path}: header has {len(header)} names for {k + 1} columns", "fix the header row"
        )
    columns = (
        header[1:]
        if header
        else (
            ["power"] if k == 1 else ["R", "G", "B"] if k == 3 else [f"c{j + 1}" for j in range(k)]
        )
    )
    return _finish(path, "csv", w, rows, columns, {})


def _oceanview_meta(header: list[str]) -> dict[str, Any]:
    meta: dict[str, Any] = {"instrument": "Ocean Insight (OceanView/SpectraSuite)"}
    for line in header:
        key, sep, value = line.partition(":")
        if not sep:
            continue
        key, value = key.strip().lower(), value.strip()
        if key in ("spectrometer", "spectrometers"):
            meta["serial"] = value
        elif key == "date":
            meta["date"] = value
        elif key == "user":
            meta["operator"] = value
        elif key.startswith("integration time"):
            num = re.match(r"[-+0-9.,Ee]+", value)
            if num:  # the key names the unit: (usec), (msec) or (sec)
                number = _number(num.group(0), "," in num.group(0))
                to_seconds = 1e-6 if "usec" in key else 1e-3 if "msec" in key else 1.0
                meta["integration_time_ms"] = number * to_seconds * 1e3
        elif key.startswith("scans to average") or key.startswith("spectra averaged"):
            meta["scans_averaged"] = value.split()[0]
    return meta


def read_oceanview(path: str | Path) -> ImportedSpectrum:
    """Ocean Insight OceanView / SpectraSuite text export."""
    path = Path(path)
    lines = _read_text(path)
    begin = next((i for i, ln in enumerate(lines) if _BEGIN.search(ln)), None)
    if begin is None:
        raise RigError(
            f"{path} has no '>>>>>Begin Spectral Data<<<<<' line: not an OceanView text export",
            "export with File > Save > Tab-delimited (with header), or use --format csv",
        )
    meta = _oceanview_meta(lines[:begin])
    w: list[float] = []
    rows: list[list[float]] = []
    for offset, line in enumerate(lines[begin + 1 :]):
        if _END.search(line):
            break
        if not line.strip():
            continue
        cells = line.replace(";", "\t").split("\t") if "\t" in line or ";" in line else line.split()
        lineno = begin + 2 + offset
        if len(cells) < 2:
            raise RigError(
                f"{path}:{lineno}: expected 'wavelength<TAB>value'", "re-export the spectrum"
            )
        try:
            w.append(_number(cells[0], True))
            rows.append([_number(cells[-1], True)])
        except ValueError as error:
            raise RigError(
                f"{path}:{lineno}: not a number ({error})", "re-export the spectrum"
            ) from error
    return _finish(path, "oceanview", w, rows, ["power"], meta)


def read_spectrawiz(path: str | Path) -> ImportedSpectrum:
    """StellarNet SpectraWiz text file (.IRR, .SSM, .ABS, .TRM)."""
    path = Path(path)
    lines = _read_text(path)
    meta: dict[str, Any] = {"instrument": "StellarNet (SpectraWiz)"}
    quantity = SPECTRAWIZ_SUFFIXES.get(path.suffix.lower())
    if quantity:
        meta["quantity"] = quantity
    w: list[float] = []
    rows: list[list[float]] = []
    header_seen = False
    for lineno, line in enumerate(lines, start=1):
        text = line.strip()
        if not text:
            continue
        if text.startswith('"'):
            header_seen = True
            inner = text.strip('"').strip()
            it = re.search(
                r"(?:int(?:egration)?\.?\s*time|itime)\s*[=:]?\s*([0-9.]+)\s*(ms|msec|us|usec|s|sec)?",
                inner,
                re.IGNORECASE,
            )
            if it:
                unit = (it.group(2) or "ms").lower()
                factor = {"ms": 1.0, "msec": 1.0, "us": 1e-3, "usec": 1e-3, "s": 1e3, "sec": 1e3}[
                    unit
                ]
                meta["integration_time_ms"] = float(it.group(1)) * factor
            if "spectrawiz" in inner.lower() or "stellarnet" in inner.lower():
                meta.setdefault("software", inner)
            continue
        cells = re.split(r"[\s,;]+", text)
        if len(cells) < 2:
            raise RigError(
                f"{path}:{lineno}: expected 'wavelength value'", "re-save the file from SpectraWiz"
            )
        try:
            w.append(float(cells[0]))
            rows.append([float(cells[-1])])
        except ValueError as error:
            raise RigError(
                f"{path}:{lineno}: not a number ({error})", "re-save the file from SpectraWiz"
            ) from error
    if not header_seen and not w:
        raise RigError(f"{path} is empty", "re-save the file from SpectraWiz")
    return _finish(path, "spectrawiz", w, rows, [quantity or "power"], meta)


def detect_format(path: str | Path) -> str:
    """Guess ``oceanview``, ``spectrawiz`` or ``csv`` from the suffix and content."""
    path = Path(path)
    if path.suffix.lower() in SPECTRAWIZ_SUFFIXES:
        return "spectrawiz"
    head = "\n".join(_read_text(path)[:60])
    if _BEGIN.search(head):
        return "oceanview"
    if head.lstrip().startswith('"') and re.search(r"spectrawiz|stellarnet", head, re.IGNORECASE):
        return "spectrawiz"
    return "csv"


def read_colour_dataset(name: str) -> ImportedSpectrum:
    """A colour-science dataset by name (illuminant, light source or camera sensitivity)."""
    for cam in defaults.camera_names():
        if name.lower() == cam.lower():
            w, rgb = defaults.camera_sensitivity_native(cam)
            meta = {"source": defaults.camera_source_description(cam)}
            return ImportedSpectrum(w, rgb, ["R", "G", "B"], "colour", f"colour:{name}", meta)
    for label, table in (
        ("colour.SDS_ILLUMINANTS", colour.SDS_ILLUMINANTS),
        ("colour.SDS_LIGHT_SOURCES", colour.SDS_LIGHT_SOURCES),
    ):
        match = next((k for k in table if k.lower() == name.lower()), None)
        if match is not None:
            sd = table[match]
            meta = {"source": f"colour-science {colour.__version__} {label}[{match!r}]"}
            return ImportedSpectrum(
                np.asarray(sd.wavelengths, float),
                np.asarray(sd.values, float)[:, None],
                ["power"],
                "colour",
                f"colour:{name}",
                meta,
            )
    match = next((k for k in colour.MSDS_CAMERA_SENSITIVITIES if k.lower() == name.lower()), None)
    if match is not None:
        msds = colour.MSDS_CAMERA_SENSITIVITIES[match]
        meta = {
            "source": f"colour-science {colour.__version__} "
            f"colour.MSDS_CAMERA_SENSITIVITIES[{match!r}]"
        }
        return ImportedSpectrum(
            np.asarray(msds.wavelengths, float),
            np.asarray(msds.values, float),
            ["R", "G", "B"],
            "colour",
            f"colour:{name}",
            meta,
        )
    raise RigError(
        f"no colour-science dataset named {name!r}",
        "use a CIE illuminant (D65, A, FL2, LED-B1...), a light source from "
        "colour.SDS_LIGHT_SOURCES, or a camera: " + ", ".join(defaults.camera_names()),
    )


def read_spectrum(path_or_name: str | Path, fmt: str = "auto") -> ImportedSpectrum:
    """Read a file in ``fmt`` (see :data:`FORMATS`) or a ``colour:NAME`` dataset."""
    text = str(path_or_name)
    if text.startswith("colour:"):
        return read_colour_dataset(text.split(":", 1)[1])
    if fmt not in FORMATS:
        raise RigError(f"unknown spectrum format {fmt!r}", f"use one of {', '.join(FORMATS)}")
    path = Path(path_or_name)
    if not path.is_file():
        raise RigError(f"spectrum file {path} does not exist", "check the path")
    if fmt == "auto":
        fmt = detect_format(path)
    reader = {"csv": read_table, "oceanview": read_oceanview, "spectrawiz": read_spectrawiz}[fmt]
    return reader(path)


def read_reflectance_set(path: str | Path) -> tuple[list[str], np.ndarray, np.ndarray]:
    """A set of reflectances: ``(labels, wavelengths (W,), values (M, W))``.

    Two layouts are accepted: one row per sample with wavelengths as the header
    (``label,380,385,...`` — the Munsell file's layout), or one column per sample
    (``wavelength_nm,sample1,sample2,...``). Values must lie in 0..1 (percent is rejected).
    """
    path = Path(path)
    lines = [ln for ln in _read_text(path) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise RigError(f"reflectance file {path} is empty", "give one reflectance per row")
    delimiter = "\t" if "\t" in lines[0] else ";" if ";" in lines[0] else ","
    header = [c.strip().strip('"') for c in lines[0].split(delimiter)]
    try:
        head_wl = [float(c) for c in header[1:]]
    except ValueError:
        head_wl = []
    if len(head_wl) >= 4 and all(250 <= x <= 1100 for x in head_wl):
        labels: list[str] = []
        rows: list[list[float]] = []
        for lineno, line in enumerate(lines[1:], start=2):
            cells = [c.strip() for c in line.split(delimiter)]
            if len(cells) != len(header):
                raise RigError(
                    f"{path}:{lineno}: {len(cells)} values, header has {len(header)}",
                    "every row needs a label and one value per wavelength",
                )
            try:
                rows.append([float(c) for c in cells[1:]])
            except ValueError as error:
                raise RigError(
                    f"{path}:{lineno}: not a number ({error})", "fix that row"
                ) from error
            labels.append(cells[0].strip('"'))
        if not rows:
            raise RigError(f"reflectance file {path} has a header but no rows", "add reflectances")
        wl = np.array(head_wl)
        values = np.array(rows)
    else:
        table = read_table(path)
        labels, wl, values = table.columns, table.wavelengths_nm, table.values.T
    validate_spectrum(wl, values.T, source=str(path), nonnegative=True)
    if np.nanmax(values) > 1.5:
        raise RigError(
            f"{path}: reflectances up to {np.nanmax(values):g} — looks like percent",
            "divide the values by 100 (reflectance must be in 0..1)",
        )
    return labels, wl, values
