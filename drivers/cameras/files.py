"""Safe placement of delivered frames: temporary name, fsync, rename
(docs/architecture.md, Reliability)."""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
from collections.abc import Callable
from pathlib import Path

from core.errors import RigError

log = logging.getLogger(__name__)


def target_path(out_dir: Path, stem: str, suffix: str, taken: set[Path]) -> Path:
    """``stem`` + lower-case suffix; a second file with the same suffix gets ``-1``, ``-2``..."""
    base = out_dir / f"{stem}{suffix.lower()}"
    path, n = base, 0
    while path in taken or path.exists():
        n += 1
        path = out_dir / f"{stem}-{n}{suffix.lower()}"
    taken.add(path)
    return path


def _place_durably(path: Path, fill: Callable[[Path], object], what: str) -> None:
    """``fill`` a temporary file, fsync it, rename it to ``path``: a crash leaves either the
    whole frame or a ``.part`` file, never a truncated frame under its real name."""
    tmp = path.with_name(path.name + ".part")
    try:
        fill(tmp)
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except OSError as error:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        raise RigError(
            f"cannot write {what} to {path}: {error.strerror or error}",
            "check disk space and permissions of the session directory",
        ) from error


def write_durably(path: Path, data: bytes) -> None:
    _place_durably(path, lambda tmp: tmp.write_bytes(data), "a downloaded frame")


def copy_durably(source: Path, path: Path, move: bool = False) -> None:
    """Copy ``source`` to ``path``; with ``move`` delete the source once the copy is safe."""
    _place_durably(path, lambda tmp: shutil.copyfile(source, tmp), f"a copy of {source}")
    if move:
        try:
            source.unlink()
        except OSError as error:  # the frame is safe; a leftover source costs only disk space
            log.warning("could not remove %s after copying it: %s", source, error)
