"""Safe file writes and content hashes shared by capture and reconstruction: a crash leaves the
old file or the new one, never half of either, and a failed write (a full disk) leaves neither
a partial file nor its temporary copy, with one line naming the path (:mod:`core.fserrors`)."""

from __future__ import annotations

import contextlib
import hashlib
import os
from collections.abc import Iterator
from pathlib import Path

from core.fserrors import fs_error, underlying_fs_error


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


def temporary_name(path: Path) -> Path:
    """The hidden name ``path`` is written under before the rename; it keeps the suffix, as
    writers that pick the format by it (matplotlib, NumPy) need."""
    return path.with_name(f".{path.stem}.tmp{path.suffix}")


@contextlib.contextmanager
def atomic_output(path: Path | str) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` for a writer that takes a file name; when the
    block ends the file is fsynced and renamed to ``path``. A failure removes the temporary
    file and raises a RigError naming ``path`` for a file-system error."""
    path = Path(path)
    tmp = temporary_name(path)
    try:
        yield tmp
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException as error:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        # any OSError here is about this file, even one without an errno (NumPy's short write)
        cause = error if isinstance(error, OSError) else underlying_fs_error(error)
        if cause is not None:
            raise fs_error(cause, path) from error
        raise
    fsync_dir(path.parent)


def write_bytes_atomically(path: Path, data: bytes) -> None:
    """Temporary name, fsync, rename, fsync the directory: a crash leaves old or new, never half."""
    with atomic_output(path) as tmp, open(tmp, "wb") as handle:
        handle.write(data)
        handle.flush()
