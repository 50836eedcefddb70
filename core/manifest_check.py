"""Checks of one manifest line before it becomes a FrameRecord: every key of the right type
and every path inside the session, so a hand-edited or hostile manifest gives one clear
error (file, line, key, fix) instead of a crash deep in reconstruction or a read outside
the session; and the checks of the manifest as a whole (:func:`session_problems`) that
`rig session verify` lists and resume and reconstruction refuse alike."""

from __future__ import annotations

import math
import os
import re
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any, Protocol

from core.errors import RigError

FIX = "restore manifest.jsonl from a backup or remove that line, then run `rig session verify`"
_SHA256 = re.compile(r"^[0-9a-f]{64}$")
# Beyond any camera's settings (a day's exposure, ISO 10 million): larger is a broken line, and
# would overflow the exposure normalisation of the decoded values.
MAX_EXPOSURE_S = 86_400.0
MAX_ISO = 1e7
LINK_FIX = "replace the link with the file itself (inside the session), or restore the session"


def _bad(where: str, key: str, value: Any, want: str) -> RigError:
    shown = repr(value)
    shown = shown if len(shown) <= 60 else shown[:57] + "..."
    return RigError(f"{where}: `{key}` is {shown}, expected {want}", FIX)


def confined_path(value: Any, where: str, key: str = "path") -> str:
    """A relative POSIX path that stays inside the session (no ``..``, no absolute path, no
    drive letter); returned unchanged."""
    if not isinstance(value, str) or not value:
        raise _bad(where, key, value, "a file path relative to the session folder")
    posix, windows = PurePosixPath(value), PureWindowsPath(value)
    if posix.is_absolute() or windows.drive or windows.root or "\\" in value:
        raise _bad(where, key, value, "a path relative to the session folder (raw/...)")
    if ".." in posix.parts or "\x00" in value:
        raise _bad(where, key, value, "a path inside the session folder (no `..`)")
    return value


def _whole(data: Mapping[str, Any], key: str, where: str) -> None:
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise _bad(where, key, value, "a whole number >= 0")


def _positive(data: Mapping[str, Any], key: str, where: str, most: float) -> None:
    value = data[key]
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not ok or not math.isfinite(value) or not 0 < value <= most:
        raise _bad(where, key, value, f"a positive number up to {most:g}")


def check_line(data: Any, where: str, n_views: int | None = None) -> None:
    """Raise RigError naming ``where`` and the key when a decoded manifest line is malformed;
    ``n_views`` (the plan's) bounds ``view``."""
    if not isinstance(data, dict):
        raise RigError(f"{where} is not a JSON object ({type(data).__name__})", FIX)
    _whole(data, "frame", where)
    _whole(data, "view", where)
    if n_views is not None and data["view"] >= n_views:
        raise _bad(where, "view", data["view"], f"a view of the plan (0..{n_views - 1})")
    for key in ("illumination", "timestamp"):
        if not isinstance(data[key], str) or not data[key]:
            raise _bad(where, key, data[key], "a non-empty string")
    if not isinstance(data["sha256"], str) or not _SHA256.match(data["sha256"]):
        raise _bad(where, "sha256", data["sha256"], "64 lowercase hex digits")
    frame = f"{where}: frame {data['frame']}"  # a broken value is named with its frame
    _positive(data, "exposure_s", frame, MAX_EXPOSURE_S)
    _positive(data, "iso", frame, MAX_ISO)
    confined_path(data["path"], where)
    extra = data.get("extra", {})
    if not isinstance(extra, dict):
        raise _bad(where, "extra", extra, "a JSON object")
    others = {**data, **extra}.get("other_files", [])
    if not isinstance(others, list):
        raise _bad(where, "other_files", others, "a list of {path, sha256}")
    for i, other in enumerate(others):
        if not isinstance(other, dict) or not isinstance(other.get("sha256"), str):
            raise _bad(where, f"other_files[{i}]", other, "{path, sha256}")
        confined_path(other.get("path"), where, f"other_files[{i}].path")


def leads_out(root: Path, path: Path) -> bool:
    """Whether ``path`` is, or lies under, a link whose target is outside ``root`` (a link
    loop counts as out)."""
    try:
        return not path.resolve().is_relative_to(root.resolve())
    except (OSError, RuntimeError):
        return True


class _Line(Protocol):
    """A checked manifest line (core.manifest.FrameRecord, which imports this module)."""

    @property
    def frame(self) -> int: ...

    @property
    def path(self) -> str: ...

    @property
    def extra(self) -> dict[str, Any]: ...


def session_problems(root: Path, records: Sequence[_Line]) -> list[tuple[str, str]]:
    """What makes a session's manifest unusable however its frames' contents check out, as
    (kind, description): a frame listed twice, a file named by two lines, a frame file that
    leads out of the session. `rig session verify` lists them; resume and reconstruct refuse
    the first (:func:`check_session`)."""
    problems: list[tuple[str, str]] = []
    counts = Counter(r.frame for r in records)
    problems += [
        ("duplicate", f"frame {frame} appears {n} times")
        for frame, n in sorted(counts.items())
        if n > 1
    ]
    owners: dict[str, list[int]] = {}
    for record in records:
        others = record.extra.get("other_files", [])
        for path in [record.path, *(o["path"] for o in others if isinstance(o, dict))]:
            owners.setdefault(path, []).append(record.frame)
    problems += [
        ("duplicate", f"{path} is the file of frames {', '.join(map(str, frames))}")
        for path, frames in owners.items()
        if len(frames) > 1 and len(set(frames)) > 1
    ]
    problems += [
        ("link out", f"{path} (frame {frames[0]}) is a link out of the session, to "
         f"{(root / path).resolve()}")
        for path, frames in owners.items()
        if os.path.lexists(root / path) and leads_out(root, root / path)
    ]
    return problems


def check_session(root: Path, records: Sequence[_Line], manifest: Path) -> None:
    """Raise RigError for the first of :func:`session_problems`."""
    for kind, problem in session_problems(root, records):
        if kind == "link out":
            raise RigError(f"{root}: {problem}: frames are read only inside it", LINK_FIX)
        raise RigError(
            f"{manifest}: {problem}",
            "the manifest was edited by hand; restore it from a backup (`rig session verify` "
            "lists every problem)",
        )
