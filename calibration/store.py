"""The calibration store: a directory of spectrum CSVs plus a YAML index with provenance.

Layout (docs/architecture.md, Calibration store)::

    STORE/
      index.yaml                  format, then one record per entry *version*
      lights/bulb__r.v1.csv       wavelength_nm,power
      cameras/canon...v1.csv      wavelength_nm,R,G,B
      flat_fields/<name>.v1.yaml  a lens fall-off model (calibration.flat_field)

Spectra are stored at their measured sampling and resampled on read, so the store is
independent of the grid. Adding a spectrum under an existing name creates the next version;
old versions stay on disk and in the index until removed explicitly. The index is rewritten
atomically (temporary file, fsync, rename); every change re-reads it under the store's lock
(core.lock), so two commands adding entries at once keep both.
"""

from __future__ import annotations

import contextlib
import csv
import datetime as _dt
import hashlib
import os
import re
import shutil
from collections.abc import Callable, Mapping
from contextlib import AbstractContextManager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from calibration import defaults
from calibration.flat_field import FlatField
from calibration.grid import DEFAULT_GRID, SpectralGrid
from calibration.spectra import resample, validate_spectrum
from core.errors import RigError
from core.files import write_bytes_atomically
from core.lock import locked
from core.yamlio import load_yaml, yaml_problem

FORMAT = "spectral-rig-calibration/1"
ENV_STORE = "SPECTRAL_RIG_STORE"
INDEX = "index.yaml"
KINDS: tuple[str, ...] = ("light", "camera", "flat_field")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+\- /]*$")
# A change holds the lock for milliseconds; a holder for longer is stuck or a whole init-store.
STORE_WAIT_S = 30.0


def value_columns(kind: str) -> list[str]:
    """The CSV value columns of a store entry of ``kind``: power, or R,G,B
    (docs/architecture.md, Calibration store)."""
    return ["power"] if kind == "light" else ["R", "G", "B"]


@dataclass
class Entry:
    """One version of one named spectrum (or flat field)."""

    name: str
    kind: str
    version: int
    file: str
    added: str
    sha256: str
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def columns(self) -> list[str]:
        return value_columns(self.kind)


def default_store_path() -> Path:
    """``$SPECTRAL_RIG_STORE`` or ``~/.local/share/spectral-rig/calibration``."""
    env = os.environ.get(ENV_STORE)
    return Path(env).expanduser() if env else Path.home() / ".local/share/spectral-rig/calibration"


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def write_spectrum_csv(
    path: Path, wavelengths: np.ndarray, values: np.ndarray, columns: list[str]
) -> None:
    """CSV with header ``wavelength_nm,<columns>`` (written atomically)."""
    lines = [",".join(["wavelength_nm", *columns])]
    for w, row in zip(wavelengths, np.atleast_2d(values.T).T, strict=True):
        lines.append(",".join([f"{w:.6g}", *(f"{x:.9g}" for x in np.atleast_1d(row))]))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_bytes_atomically(path, ("\n".join(lines) + "\n").encode("utf-8"))


def read_spectrum_csv(path: Path, columns: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Read a store CSV, checking its header; returns (wavelengths (M,), values (M, k))."""
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            rows = list(csv.reader(handle))
    except OSError as error:
        raise RigError(
            f"cannot read calibration file {path}: {error}", "restore it or re-import"
        ) from error
    expected = ["wavelength_nm", *columns]
    if not rows or [c.strip() for c in rows[0]] != expected:
        raise RigError(
            f"calibration file {path} has header {rows[0] if rows else '(empty)'}",
            f"the header must be {','.join(expected)}",
        )
    try:
        data = np.array([[float(x) for x in r] for r in rows[1:] if r], dtype=float)
    except ValueError as error:
        raise RigError(
            f"calibration file {path}: non-numeric value ({error})", "fix or re-import it"
        ) from error
    if data.ndim != 2 or data.shape[1] != len(expected):
        raise RigError(
            f"calibration file {path}: rows do not all have {len(expected)} values",
            "fix or re-import it",
        )
    w, v = validate_spectrum(data[:, 0], data[:, 1:], source=str(path))
    return w, v


class CalibrationStore:
    """A calibration store directory (see module docstring)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root).expanduser()
        self._entries: list[Entry] = self._read_index()

    # -- index -----------------------------------------------------------------------------
    @property
    def index_path(self) -> Path:
        return self.root / INDEX

    def _read_index(self) -> list[Entry]:
        if not self.index_path.exists():
            return []
        try:
            data = load_yaml(self.index_path.read_text(encoding="utf-8")) or {}
        except (yaml.YAMLError, UnicodeDecodeError) as error:
            problem = yaml_problem(error) if isinstance(error, yaml.YAMLError) else "not UTF-8"
            raise RigError(
                f"calibration index {self.index_path} is not valid YAML: {problem}",
                "fix the file or restore it from a session's calibration/ snapshot",
            ) from error
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise RigError(
                f"{self.index_path} is not a spectral-rig calibration index (format: {FORMAT})",
                "point --store at a directory made by `rig calibrate init-store`",
            )
        entries = []
        for i, record in enumerate(data.get("entries") or []):
            try:
                entry = Entry(**record)
            except TypeError as error:
                raise RigError(
                    f"{self.index_path}: entry {i + 1} is malformed ({error})",
                    "each entry needs name, kind, version, file, added, sha256, provenance",
                ) from error
            if entry.kind not in KINDS:
                raise RigError(
                    f"{self.index_path}: entry {entry.name!r} has kind {entry.kind!r}",
                    f"use one of {', '.join(KINDS)}",
                )
            if not isinstance(entry.version, int) or not isinstance(entry.provenance, dict):
                raise RigError(
                    f"{self.index_path}: entry {entry.name!r} has version {entry.version!r} "
                    f"and provenance of type {type(entry.provenance).__name__}",
                    "the version must be a whole number and the provenance a mapping",
                )
            self._confine(entry)
            entries.append(entry)
        return entries

    def _confine(self, entry: Entry) -> None:
        """An entry's ``file:`` must name a file inside the store, so reading a foreign store,
        snapshotting it into a session or `rig calibrate remove` never reaches outside it
        (no absolute path, no ``..``, no symlink leading out)."""
        file = entry.file
        inside = isinstance(file, str) and bool(file) and "\x00" not in file
        if inside:
            rel = Path(file)
            inside = not rel.is_absolute() and ".." not in rel.parts and "\\" not in file
        if inside:
            root = self.root.resolve()
            inside = (root / file).resolve().is_relative_to(root)
        if not inside:
            raise RigError(
                f"{self.index_path}: entry {entry.name!r} v{entry.version} has "
                f"file: {file!r}, which is not a file inside the store",
                "entries name files under lights/, cameras/ or flat_fields/ of the store; restore "
                "index.yaml from a backup or a session's calibration/ snapshot",
            )

    def _write_index(self) -> None:
        self.root.mkdir(parents=True, exist_ok=True)
        data = {"format": FORMAT, "entries": [asdict(e) for e in self._entries]}
        text = yaml.safe_dump(data, sort_keys=False, allow_unicode=True)
        write_bytes_atomically(self.index_path, text.encode("utf-8"))

    # -- queries ---------------------------------------------------------------------------
    def entries(self, kind: str | None = None, *, all_versions: bool = True) -> list[Entry]:
        """Entries (every version by default; ``all_versions=False``: latest of each name)."""
        out = [e for e in self._entries if kind is None or e.kind == kind]
        if not all_versions:
            latest: dict[str, Entry] = {}
            for e in out:
                if e.name not in latest or e.version > latest[e.name].version:
                    latest[e.name] = e
            out = list(latest.values())
        return sorted(out, key=lambda e: (e.kind, e.name, e.version))

    def names(self, kind: str | None = None) -> list[str]:
        return [e.name for e in self.entries(kind, all_versions=False)]

    def entry(self, name: str, version: int | None = None, kind: str | None = None) -> Entry:
        """The entry ``name`` (latest version unless ``version``)."""
        matches = [e for e in self._entries if e.name == name and (kind is None or e.kind == kind)]
        if not matches:
            known = ", ".join(self.names(kind)) or "(store is empty)"
            raise RigError(
                f"no {kind or 'calibration'} entry named {name!r} in {self.root}",
                f"known entries: {known}; add one with `rig calibrate import` or "
                "`rig calibrate init-store`",
            )
        if version is None:
            return max(matches, key=lambda e: e.version)
        for e in matches:
            if e.version == version:
                return e
        raise RigError(
            f"{name!r} has no version {version} in {self.root}",
            "available versions: " + ", ".join(str(v) for v in sorted(e.version for e in matches)),
        )

    def read_native(self, entry: Entry) -> tuple[np.ndarray, np.ndarray]:
        """An entry's spectrum at its stored sampling, after checking its file hash."""
        if entry.kind == "flat_field":
            raise RigError(
                f"{entry.name!r} is a flat field, not a spectrum",
                f"read it with `rig calibrate show {entry.name}` or CalibrationStore.flat_field",
            )
        return read_spectrum_csv(self._checked_file(entry), entry.columns)

    def _checked_file(self, entry: Entry) -> Path:
        """An entry's file, present and with the hash the index recorded."""
        path = self.root / entry.file
        if not path.exists():
            raise RigError(
                f"calibration file {path} for {entry.name!r} v{entry.version} is missing",
                "restore it or remove the entry",
            )
        if _sha256(path) != entry.sha256:
            raise RigError(
                f"calibration file {path} was modified after it was added (sha256 mismatch)",
                "import the edited file as a new version instead of editing files in place",
            )
        return path

    def light_spd(
        self, name: str, grid: SpectralGrid = DEFAULT_GRID, version: int | None = None
    ) -> np.ndarray:
        """Light SPD (N_λ,) on ``grid``."""
        entry = self.entry(name, version, kind="light")
        w, v = self.read_native(entry)
        return resample(
            w, v[:, 0], grid, source=f"{self.root / entry.file} ({name} v{entry.version})"
        )

    def camera(
        self, name: str, grid: SpectralGrid = DEFAULT_GRID, version: int | None = None
    ) -> np.ndarray:
        """Camera sensitivity (N_λ, 3) on ``grid``."""
        entry = self.entry(name, version, kind="camera")
        w, v = self.read_native(entry)
        return resample(w, v, grid, source=f"{self.root / entry.file} ({name} v{entry.version})")

    # -- changes ---------------------------------------------------------------------------
    def _changing(self, command: str) -> AbstractContextManager[None]:
        """Hold the store's lock (waiting for another change to end) for a read-modify-write."""
        return locked(self.root, command, wait_s=STORE_WAIT_S, create=True)

    def _add(
        self,
        name: str,
        kind: str,
        wavelengths: np.ndarray,
        values: np.ndarray,
        provenance: Mapping[str, Any],
    ) -> Entry:
        with self._changing("rig calibrate import"):
            self._entries = self._read_index()  # another command may have added since
            return self._add_unlocked(name, kind, wavelengths, values, provenance)

    def _add_unlocked(
        self,
        name: str,
        kind: str,
        wavelengths: np.ndarray,
        values: np.ndarray,
        provenance: Mapping[str, Any],
    ) -> Entry:
        columns = value_columns(kind)
        w, v = validate_spectrum(wavelengths, values, source=f"{kind} {name!r}")
        if v.shape[1] != len(columns):
            raise RigError(
                f"{kind} {name!r} has {v.shape[1]} value columns",
                f"a {kind} needs {len(columns)} ({', '.join(columns)})",
            )
        return self._add_file_unlocked(
            name, kind, "csv", lambda path: write_spectrum_csv(path, w, v, columns), provenance
        )

    def _add_file_unlocked(
        self,
        name: str,
        kind: str,
        suffix: str,
        write: Callable[[Path], None],
        provenance: Mapping[str, Any],
    ) -> Entry:
        """The next version of ``name``: its file written by ``write``, then the index."""
        if not _NAME.match(name) or ".." in name:
            raise RigError(
                f"invalid calibration entry name {name!r}",
                "use letters, digits and . _ - + / (e.g. bulb/r, LED1, canon-5d2)",
            )
        clash = [e for e in self._entries if e.name == name and e.kind != kind]
        if clash:
            raise RigError(f"{name!r} already names a {clash[0].kind} entry", "choose another name")
        version = 1 + max((e.version for e in self._entries if e.name == name), default=0)
        slug = re.sub(r"[^A-Za-z0-9._+-]", "-", name.replace("/", "__").replace(" ", "_"))
        if any(e.file.startswith(f"{kind}s/{slug}.v") for e in self._entries if e.name != name):
            slug += "-" + hashlib.sha256(name.encode()).hexdigest()[:8]  # "a b" vs "a_b"
        rel = f"{kind}s/{slug}.v{version}.{suffix}"
        path = self.root / rel
        if path.exists():
            raise RigError(f"{path} exists but is not in the index", "move it away, then add again")
        write(path)
        prov = {k: v for k, v in dict(provenance).items() if v is not None}
        entry = Entry(
            name=name,
            kind=kind,
            version=version,
            file=rel,
            added=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            sha256=_sha256(path),
            provenance=prov,
        )
        self._entries.append(entry)
        try:
            self._write_index()
        except BaseException:  # the index does not list it: leave no stray file either
            self._entries.remove(entry)
            with contextlib.suppress(OSError):
                path.unlink(missing_ok=True)
            raise
        return entry

    def add_light(
        self,
        name: str,
        wavelengths_nm: np.ndarray,
        power: np.ndarray,
        provenance: Mapping[str, Any],
    ) -> Entry:
        """Add a light SPD; an existing name gets a new version (the old one is kept)."""
        return self._add(
            name, "light", np.asarray(wavelengths_nm), np.asarray(power).reshape(-1, 1), provenance
        )

    def add_camera(
        self, name: str, wavelengths_nm: np.ndarray, rgb: np.ndarray, provenance: Mapping[str, Any]
    ) -> Entry:
        """Add a camera sensitivity (M, 3); an existing name gets a new version."""
        return self._add(name, "camera", np.asarray(wavelengths_nm), np.asarray(rgb), provenance)

    def add_flat_field(
        self, name: str, flat: FlatField, provenance: Mapping[str, Any]
    ) -> Entry:
        """Add a flat field (``flat_fields/NAME.vN.yaml``); an existing name gets a new version."""
        text = yaml.safe_dump(flat.to_dict(), sort_keys=False, allow_unicode=True)

        def write(path: Path) -> None:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_bytes_atomically(path, text.encode("utf-8"))

        with self._changing("rig calibrate flat-field"):
            self._entries = self._read_index()
            return self._add_file_unlocked(name, "flat_field", "yaml", write, provenance)

    def flat_field(self, name: str, version: int | None = None) -> tuple[Entry, FlatField]:
        """The flat field ``name`` (latest version unless ``version``), its file hash checked."""
        entry = self.entry(name, version, kind="flat_field")
        path = self._checked_file(entry)
        try:
            data = load_yaml(path.read_text(encoding="utf-8"))
        except (yaml.YAMLError, UnicodeDecodeError, OSError) as error:
            raise RigError(
                f"cannot read flat field {path}: {error}", "restore it or make it again"
            ) from error
        return entry, FlatField.from_dict(data, str(path))

    def remove(self, name: str, version: int | None = None) -> list[Entry]:
        """Remove one version (or every version) of ``name`` and its files."""
        with self._changing("rig calibrate remove"):
            self._entries = self._read_index()
            self.entry(name, version)
            gone = [
                e
                for e in self._entries
                if e.name == name and (version is None or e.version == version)
            ]
            self._entries = [e for e in self._entries if e not in gone]
            self._write_index()
        for e in gone:
            (self.root / e.file).unlink(missing_ok=True)
        return gone

    def copy_to(self, dest: str | Path) -> CalibrationStore:
        """Snapshot the store into ``dest`` (for a capture session's ``calibration/``)."""
        dest = Path(dest)
        if dest.exists() and any(dest.iterdir()):
            raise RigError(
                f"{dest} already exists and is not empty", "snapshot into a new directory"
            )
        dest.mkdir(parents=True, exist_ok=True)
        for e in self._entries:
            target = dest / e.file
            target.parent.mkdir(parents=True, exist_ok=True)
            try:
                shutil.copy2(self.root / e.file, target)
            except OSError as error:
                raise RigError(
                    f"cannot copy calibration file {self.root / e.file} ({e.name!r} "
                    f"v{e.version}) to {target}: {error.strerror or error}",
                    "restore the file or remove the entry, and check the destination's disk",
                ) from error
        snapshot = CalibrationStore(dest)
        snapshot._entries = list(self._entries)
        snapshot._write_index()  # also for a store never written (no index.yaml yet)
        return snapshot

    @classmethod
    def create_default(
        cls, root: str | Path, grid: SpectralGrid = DEFAULT_GRID
    ) -> CalibrationStore:
        """A store holding the built-in defaults, each with its source in the provenance."""
        store = cls(root)
        with store._changing("rig calibrate init-store"):
            store._entries = store._read_index()
            if store._entries:
                raise RigError(
                    f"{store.root} already holds a calibration store", "choose an empty directory"
                )
            had_index = store.index_path.exists()
            try:
                store._add_defaults(grid)
            except BaseException:  # a full disk midway: leave no half store behind
                store._discard_written(keep_index=had_index)
                raise
        return store

    def _discard_written(self, keep_index: bool) -> None:
        """Remove every entry's file this store object wrote, the index (rewritten empty when
        ``keep_index``) and the kind folders left empty (:meth:`create_default` failed
        part-way)."""
        for entry in self._entries:
            with contextlib.suppress(OSError):
                (self.root / entry.file).unlink(missing_ok=True)
        self._entries = []
        if keep_index:
            with contextlib.suppress(RigError):  # the failure being reported comes first
                self._write_index()
        else:
            with contextlib.suppress(OSError):
                self.index_path.unlink(missing_ok=True)
        for kind in KINDS:
            with contextlib.suppress(OSError):
                (self.root / f"{kind}s").rmdir()

    def _add_defaults(self, grid: SpectralGrid) -> None:
        """The built-in camera sensitivities, bulb channel models and their mixes."""
        today = _dt.date.today().isoformat()
        for cam in defaults.camera_names():
            w, rgb = defaults.camera_sensitivity_native(cam)
            notes = "built-in default, normalised to max 1"
            if w[0] > grid.start_nm or w[-1] < grid.stop_nm:
                w, rgb = grid.wavelengths, defaults.camera_sensitivity(cam, grid)
                notes += (
                    f"; extended to {grid.start_nm:g}–{grid.stop_nm:g} nm (constant extrapolation)"
                )
            source = defaults.camera_source_description(cam)
            self.add_camera(cam, w, rgb, {"source": source, "date": today, "notes": notes})
        channels = defaults.rgbcw_channel_spds(grid)
        for key, spd in channels.items():
            self.add_light(
                f"bulb/{key}",
                grid.wavelengths,
                spd,
                {
                    "source": defaults.BULB_CHANNEL_MODELS[key].describe(),
                    "date": today,
                    "notes": "MODEL, not a measurement: replace with a spectrometer measurement. "
                    "Scaled so a white reflector at 0.5 m under all channels reads 0.5 "
                    f"(camera {defaults.DEFAULT_CAMERA})",
                },
            )
        for name, levels in defaults.default_illuminations().items():
            self.add_light(
                name,
                grid.wavelengths,
                defaults.illumination_spd(levels, channels),
                {
                    "source": "mix of bulb channel models",
                    "mix": dict(levels),
                    "date": today,
                    "notes": "MODEL",
                },
            )
