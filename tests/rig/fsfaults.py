"""File-system failures simulated in-process, for the tests of how commands report them: a disk
that fills up (ENOSPC on writing, after an optional budget of bytes), a read-only file system
(EROFS on creating, changing or removing anything) and a folder the user may not write
(EACCES: a real ``chmod`` when not running as root, simulated as root, where permissions do
not apply).

Only the paths matching the given glob patterns fail (``fnmatch`` on the absolute path: ``*``
crosses ``/``), so a test can fill one folder of a session and keep the rest writable. Python's
file objects (``open``, so NumPy, matplotlib, PIL, tifffile and pathlib) and the ``os`` calls
that write, create, rename and remove are covered; writes done in C by a library are not.
"""

from __future__ import annotations

import builtins
import errno
import io
import os
import stat
from collections.abc import Iterator
from fnmatch import fnmatch
from pathlib import Path
from typing import Any

import pytest

_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND


def _error(code: int, path: object = None) -> OSError:
    return OSError(code, os.strerror(code), None if path is None else os.fsdecode(path))


class _FullFile:
    """A file object whose writes fail once the disk's budget is spent (nothing is written by
    the failing call, as the kernel does when no block is left)."""

    def __init__(self, handle: Any, faults: Faults) -> None:
        self._handle = handle
        self._faults = faults
        self._fd = handle.fileno()
        faults._fds.add(self._fd)

    def close(self) -> None:
        self._faults._fds.discard(self._fd)
        self._handle.close()

    def write(self, data: Any) -> int:
        self._faults.spend(len(data))
        return int(self._handle.write(data))

    def writelines(self, lines: Any) -> None:
        for line in lines:
            self.write(line)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._handle, name)

    def __iter__(self) -> Iterator[Any]:
        return iter(self._handle)

    def __enter__(self) -> _FullFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Faults:
    """Install failures with :meth:`full`, :meth:`read_only` or :meth:`no_permission`; undone
    by pytest's monkeypatch at the end of the test."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.monkeypatch = monkeypatch
        self._full: list[str] = []
        self._frozen: list[tuple[str, int]] = []
        self._budget = 0
        self._fds: set[int] = set()
        self._installed = False
        self._chmodded: list[tuple[Path, int]] = []

    # -- what fails ------------------------------------------------------------------------
    def full(self, *patterns: Path | str, budget: int = 0) -> None:
        """Writing to files matching ``patterns`` fails with ENOSPC once ``budget`` bytes are
        written (creating an empty file or a folder still works, as on a real full disk)."""
        self._full += [str(p) for p in patterns]
        self._budget = budget
        self._install()

    def read_only(self, *patterns: Path | str, code: int = errno.EROFS) -> None:
        """Creating, writing, renaming or removing anything matching ``patterns`` fails with
        ``code``."""
        self._frozen += [(str(p), code) for p in patterns]
        self._install()

    def no_permission(self, folder: Path) -> None:
        """``folder`` and everything in it not writable: ``chmod`` a-w when that binds the
        user, EACCES simulated for root."""
        if os.geteuid() != 0:
            for path in [folder, *folder.rglob("*")]:
                if path.is_dir() and not path.is_symlink():
                    mode = path.stat().st_mode
                    self._chmodded.append((path, mode))
                    path.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
            return
        self.read_only(folder, f"{folder}/*", code=errno.EACCES)

    def restore_permissions(self) -> None:
        for path, mode in reversed(self._chmodded):
            path.chmod(mode)
        self._chmodded.clear()

    def spend(self, size: int) -> None:
        if size and size > self._budget:
            raise _error(errno.ENOSPC)
        self._budget -= size

    # -- matching --------------------------------------------------------------------------
    @staticmethod
    def _match(path: object, patterns: list[str]) -> bool:
        try:
            text = os.path.abspath(os.fsdecode(path))  # type: ignore[arg-type]
        except TypeError:  # a file descriptor
            return False
        return any(fnmatch(text, p) for p in patterns)

    def _frozen_code(self, path: object) -> int | None:
        for pattern, code in self._frozen:
            if self._match(path, [pattern]):
                return code
        return None

    def _check(self, *paths: object) -> None:
        for path in paths:
            code = self._frozen_code(path)
            if code is not None:
                raise _error(code, path)

    # -- the patches -----------------------------------------------------------------------
    def _install(self) -> None:
        if self._installed:
            return
        self._installed = True
        real_open, real_os_open = builtins.open, os.open
        real_write, real_pwrite, real_sendfile = os.write, os.pwrite, os.sendfile
        real_close = os.close
        faults = self

        def patched_open(file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
            writing = isinstance(file, (str, bytes, os.PathLike)) and any(
                c in mode for c in "wax+"
            )
            if writing:
                faults._check(file)
            handle = real_open(file, mode, *args, **kwargs)
            if writing and faults._match(file, faults._full):
                return _FullFile(handle, faults)
            return handle

        def patched_os_open(path: Any, flags: int, *args: Any, **kwargs: Any) -> int:
            if flags & _WRITE_FLAGS and kwargs.get("dir_fd") is None:
                faults._check(path)
            fd = real_os_open(path, flags, *args, **kwargs)
            if flags & _WRITE_FLAGS and faults._match(path, faults._full):
                faults._fds.add(fd)
            return fd

        def patched_write(fd: int, data: Any) -> int:
            if fd in faults._fds:
                faults.spend(len(data))
            return real_write(fd, data)

        def patched_pwrite(fd: int, data: Any, offset: int) -> int:
            if fd in faults._fds:
                faults.spend(len(data))
            return real_pwrite(fd, data, offset)

        def patched_sendfile(out_fd: int, in_fd: int, offset: Any, count: int) -> int:
            if out_fd in faults._fds:
                faults.spend(count)
            return real_sendfile(out_fd, in_fd, offset, count)

        def patched_close(fd: int) -> None:
            faults._fds.discard(fd)
            real_close(fd)

        def guard(name: str, arity: int) -> None:
            real = getattr(os, name)

            def patched(*args: Any, **kwargs: Any) -> Any:
                if not any(k.endswith("dir_fd") and v is not None for k, v in kwargs.items()):
                    faults._check(*args[:arity])
                return real(*args, **kwargs)

            self.monkeypatch.setattr(os, name, patched)

        self.monkeypatch.setattr(builtins, "open", patched_open)
        self.monkeypatch.setattr(io, "open", patched_open)
        self.monkeypatch.setattr(os, "open", patched_os_open)
        self.monkeypatch.setattr(os, "write", patched_write)
        self.monkeypatch.setattr(os, "pwrite", patched_pwrite)
        self.monkeypatch.setattr(os, "sendfile", patched_sendfile)
        self.monkeypatch.setattr(os, "close", patched_close)
        for name, arity in (
            ("mkdir", 1), ("rename", 2), ("replace", 2), ("unlink", 1), ("remove", 1),
            ("rmdir", 1), ("symlink", 2), ("link", 2), ("utime", 1), ("chmod", 1),
            ("truncate", 1),
        ):  # fmt: skip
            guard(name, arity)
