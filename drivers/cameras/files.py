"""Safe placement of delivered frames: temporary name, fsync, rename (DESIGN.md, Reliability)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from calibration.errors import RigError


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
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


def copy_durably(source: Path, path: Path, move: bool = False) -> None:
    tmp = path.with_name(path.name + ".part")
    try:
        shutil.copyfile(source, tmp)
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except OSError as error:
        raise RigError(
            f"cannot copy {source} to {path}: {error}", "check disk space and permissions"
        ) from error
    if move:
        source.unlink()
