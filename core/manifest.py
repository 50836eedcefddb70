"""The session's ``manifest.jsonl``: one :class:`FrameRecord` per line, appended only after the
frame's file is durable; read back with every line checked (:mod:`core.manifest_check`)."""

from __future__ import annotations

import contextlib
import json
import logging
import os
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from core.errors import RigError
from core.files import sha256_file
from core.fserrors import fs_error
from core.manifest_check import LINK_FIX, check_line, leads_out

log = logging.getLogger(__name__)

MANIFEST_FILE = "manifest.jsonl"


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


def record_paths(record: FrameRecord) -> list[str]:
    """Every file a manifest line owns (the main one and any companions)."""
    others = record.extra.get("other_files", [])
    return [record.path, *(o["path"] for o in others if isinstance(o, dict) and "path" in o)]


def append_manifest(session_dir: Path, record: FrameRecord) -> None:
    """Append one line and fsync it; called only after the frame's file is durable. A failed
    write (a full disk) is cut off again, so no torn line is left behind."""
    path = session_dir / MANIFEST_FILE
    line = memoryview((record.to_json() + "\n").encode("utf-8"))
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    except OSError as error:
        raise fs_error(error, path) from error
    start = os.fstat(fd).st_size
    try:
        while line:
            line = line[os.write(fd, line) :]
        os.fsync(fd)
    except OSError as error:
        with contextlib.suppress(OSError):
            os.ftruncate(fd, start)
        raise fs_error(error, path) from error
    finally:
        os.close(fd)


def read_manifest(session_dir: Path, n_views: int | None = None) -> list[FrameRecord]:
    """All complete manifest lines, each checked (``n_views``: the plan's, bounds ``view``).
    A torn last line (a kill mid-append) is ignored with a warning — its frame is simply
    captured again on resume."""
    path = session_dir / MANIFEST_FILE
    if not os.path.lexists(path):
        return []
    if leads_out(session_dir, path):
        raise RigError(f"{path} is a link out of the session", LINK_FIX)
    if not path.is_file():
        raise RigError(
            f"{path} is not a file (a folder or a device)",
            "move it away and restore the session's manifest from a backup",
        )
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
    """Re-hash every frame; report missing files, mismatching hashes and files that lead out
    of the session (never read)."""
    problems = []
    for record in records:
        file = session_dir / record.path
        if os.path.lexists(file) and leads_out(session_dir, file):
            problems.append(FrameProblem(record, "link out"))
        elif not file.is_file():
            problems.append(FrameProblem(record, "missing"))
        elif sha256_file(file) != record.sha256:
            problems.append(FrameProblem(record, "hash mismatch"))
    return problems
