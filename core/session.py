"""The session directory, a public format (docs/architecture.md, Session format): layout,
manifest, safe writes.

Capture writes it (``rig.capture``); reconstruction reads it. It lives here because
``reconstruct`` may not import ``rig``, and both need the same definition.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import yaml

from core.errors import RigError
from core.manifest_check import check_line
from core.yamlio import load_yaml, yaml_problem

log = logging.getLogger(__name__)

SESSION_FILE = "session.yaml"
MANIFEST_FILE = "manifest.jsonl"
RAW_DIR = "raw"
CALIBRATION_DIR = "calibration"
POSES_DIR = "poses"
RECON_DIR = "recon"


@dataclass(frozen=True)
class FrameRecord:
    """One manifest line: a frame whose file is safely on disk."""

    frame: int
    view: int
    illumination: str  # illumination name, "ambient", or a structured-light pattern id
    path: str  # relative to the session directory, POSIX separators
    sha256: str
    exposure_s: float
    iso: float
    timestamp: str
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_dict(
        cls, data: dict[str, Any], where: str, n_views: int | None = None
    ) -> FrameRecord:
        if not isinstance(data, dict):
            check_line(data, where)
        missing = [k for k in cls.__dataclass_fields__ if k not in data and k != "extra"]
        if missing:
            raise RigError(f"{where} lacks {', '.join(missing)}", "the manifest line is malformed")
        check_line(data, where, n_views)
        known = {k: data[k] for k in cls.__dataclass_fields__ if k in data}
        extra = {k: v for k, v in data.items() if k not in cls.__dataclass_fields__}
        known.setdefault("extra", {})
        known["extra"] = {**known["extra"], **extra}
        return cls(**known)


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while block := handle.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def fsync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable (no-op where directories cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_bytes_atomically(path: Path, data: bytes) -> None:
    """Temporary name, fsync, rename, fsync the directory: a crash leaves old or new, never half."""
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)
    fsync_dir(path.parent)


def append_manifest(session_dir: Path, record: FrameRecord) -> None:
    """Append one line and fsync it; called only after the frame's file is durable."""
    path = session_dir / MANIFEST_FILE
    with open(path, "a", encoding="utf-8") as handle:
        handle.write(record.to_json() + "\n")
        handle.flush()
        os.fsync(handle.fileno())


def read_manifest(session_dir: Path, n_views: int | None = None) -> list[FrameRecord]:
    """All complete manifest lines, each checked (``n_views``: the plan's, bounds ``view``).
    A torn last line (a kill mid-append) is ignored with a warning — its frame is simply
    captured again on resume."""
    path = session_dir / MANIFEST_FILE
    if not path.is_file():
        return []
    records: list[FrameRecord] = []
    lines = path.read_bytes().split(b"\n")
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            data = json.loads(line.decode("utf-8"))
        except UnicodeDecodeError as exc:
            if number == len(lines):  # last line, not newline-terminated: torn write
                log.warning("%s: ignoring the torn last line %d", path, number)
                continue
            raise RigError(
                f"{path} line {number} is not text (byte {exc.start}: binary data)",
                "restore the manifest from a backup or remove that line and run "
                "`rig session verify`",
            ) from exc
        except json.JSONDecodeError as exc:
            if number == len(lines):  # last line, not newline-terminated: torn write
                log.warning("%s: ignoring the torn last line %d", path, number)
                continue
            raise RigError(
                f"{path} line {number} is not valid JSON ({exc.msg})",
                "restore the manifest from a backup or remove that line and run "
                "`rig session verify`",
            ) from exc
        records.append(FrameRecord.from_dict(data, f"{path} line {number}", n_views))
    return records


@dataclass(frozen=True)
class FrameProblem:
    record: FrameRecord
    problem: str  # "missing" or "hash mismatch"


def verify_frames(session_dir: Path, records: Iterable[FrameRecord]) -> list[FrameProblem]:
    """Re-hash every frame; report missing files and mismatching hashes."""
    problems = []
    for record in records:
        file = session_dir / record.path
        if not file.is_file():
            problems.append(FrameProblem(record, "missing"))
        elif sha256_file(file) != record.sha256:
            problems.append(FrameProblem(record, "hash mismatch"))
    return problems


def _planned_views(info: dict[str, Any]) -> int | None:
    """The capture plan's view count, which bounds the manifest's ``view`` (sessions written
    by other tools may have no plan)."""
    plan = info.get("plan") if isinstance(info, dict) else None
    views = plan.get("views") if isinstance(plan, dict) else None
    return views if isinstance(views, int) and not isinstance(views, bool) and views > 0 else None


@dataclass
class Session:
    """A session directory opened for reading."""

    root: Path
    info: dict[str, Any]
    frames: list[FrameRecord]

    @classmethod
    def open(cls, root: Path, bound_views: bool = True) -> Session:
        """The session at ``root``; a manifest line naming a view beyond the plan is an error
        unless ``bound_views`` is False (`rig session verify` lists such lines instead)."""
        root = Path(root)
        meta = root / SESSION_FILE
        if not meta.is_file():
            raise RigError(
                f"{root} is not a session directory (no {SESSION_FILE})",
                "give the folder that `rig capture --out` created",
            )
        try:
            info = load_yaml(meta.read_text(encoding="utf-8")) or {}
        except (yaml.YAMLError, UnicodeDecodeError) as exc:
            problem = yaml_problem(exc) if isinstance(exc, yaml.YAMLError) else "not UTF-8 text"
            raise RigError(
                f"{meta} is not valid YAML: {problem}", "fix the file (repeated keys, syntax)"
            ) from exc
        n_views = _planned_views(info) if bound_views else None
        return cls(root, info, read_manifest(root, n_views))

    @property
    def raw_dir(self) -> Path:
        return self.root / RAW_DIR

    @property
    def calibration_dir(self) -> Path:
        return self.root / CALIBRATION_DIR

    @property
    def poses_dir(self) -> Path:
        return self.root / POSES_DIR

    @property
    def recon_dir(self) -> Path:
        return self.root / RECON_DIR

    def views(self) -> list[int]:
        return sorted({f.view for f in self.frames})

    def frames_of_view(self, view: int) -> list[FrameRecord]:
        return [f for f in self.frames if f.view == view]
