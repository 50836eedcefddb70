"""Safe placement of delivered frames: temporary name, fsync, rename
(docs/architecture.md, Reliability)."""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

from core.files import atomic_output

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


def write_durably(path: Path, data: bytes) -> None:
    """A crash leaves the whole frame or a hidden temporary file, never a truncated frame."""
    with atomic_output(path) as tmp:
        tmp.write_bytes(data)


def copy_durably(source: Path, path: Path, move: bool = False) -> None:
    """Copy ``source`` to ``path``; with ``move`` delete the source once the copy is safe."""
    with atomic_output(path) as tmp:
        shutil.copyfile(source, tmp)
    if move:
        try:
            source.unlink()
        except OSError as error:  # the frame is safe; a leftover source costs only disk space
            log.warning("could not remove %s after copying it: %s", source, error)
