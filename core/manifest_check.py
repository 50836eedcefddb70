"""Checks of one manifest line before it becomes a FrameRecord: every key of the right type
and every path inside the session, so a hand-edited or hostile manifest gives one clear
error (file, line, key, fix) instead of a crash deep in reconstruction or a read outside
the session."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from pathlib import PurePosixPath, PureWindowsPath
from typing import Any

from core.errors import RigError

FIX = "restore manifest.jsonl from a backup or remove that line, then run `rig session verify`"
_SHA256 = re.compile(r"^[0-9a-f]{64}$")


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


def _positive(data: Mapping[str, Any], key: str, where: str) -> None:
    value = data[key]
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not ok or not math.isfinite(value) or value <= 0:
        raise _bad(where, key, value, "a positive number")


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
    _positive(data, "exposure_s", where)
    _positive(data, "iso", where)
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
