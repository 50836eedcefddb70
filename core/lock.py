"""One writer at a time per folder: a session (capture, resume, reconstruct, relight, evaluate,
view export) or a calibration store (its ``index.yaml`` read-modify-write).

The lock is an OS advisory lock (``flock``) on ``FOLDER/.lock``, so the kernel releases it
however its process ends: a lock file left by a killed process never blocks the next command.
The holder writes who it is into the file (PID, host, command, since) so a refused command
says in one line who has the folder. The file is removed on release (before unlocking, and a
command that locked a file since removed tries again), so a folder keeps no ``.lock`` after a
normal run.

Holding is re-entrant per thread (a capture's reconstruction, ``run_logged`` around
``run_reconstruction``); another thread of the same process is refused like another process.
Linux and macOS only: Windows has no ``flock`` and is not a target of the project.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import errno
import fcntl
import json
import os
import socket
import stat
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from core.errors import RigError
from core.fserrors import fs_error
from core.session import SESSION_FILE

LOCK_FILE = ".lock"
POLL_S = 0.05
HOLDER_WAIT_S = 0.5  # a holder writes its description right after locking


class InUse(RigError):
    """The folder is locked by another command."""


@dataclass
class _Hold:
    fd: int
    depth: int
    created: tuple[Path, ...]  # folders made for this hold, deepest first: removed if empty


_local = threading.local()


def _holds() -> dict[Path, _Hold]:
    if not hasattr(_local, "holds"):
        _local.holds = {}
    held: dict[Path, _Hold] = _local.holds
    return held


def _now() -> str:
    return dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def _open(path: Path) -> int:
    """The lock file, created if missing; never through a link (the holder writes into it)."""
    remove = f"remove {path} (a lock file that commands recreate)"
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    except OSError as error:
        if error.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
            fix = f"make {path.parent} writable, or copy it to a writable disk"
        elif error.errno == errno.ENOENT:
            fix = "give an existing folder"
        else:
            fix = remove
        raise RigError(f"cannot open the lock file {path} ({error.strerror})", fix) from error
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode) or info.st_nlink > 1:
        os.close(fd)
        what = "has other names (a hard link)" if info.st_nlink > 1 else "is not a plain file"
        raise RigError(f"the lock file {path} {what}", remove)
    return fd


def _try_lock(fd: int, path: Path) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError as error:
        raise RigError(
            f"cannot lock {path} ({error.strerror})",
            "keep the folder on a local disk (this file system has no locks)",
        ) from error
    return True


def _is_current(fd: int, path: Path) -> bool:
    """``fd`` is still the file at ``path`` (its holder did not remove it meanwhile)."""
    try:
        now = os.stat(path, follow_symlinks=False)
    except FileNotFoundError:
        return False
    mine = os.fstat(fd)
    return (now.st_dev, now.st_ino) == (mine.st_dev, mine.st_ino)


def _read_holder(fd: int) -> dict[str, object]:
    """The description its holder wrote (empty if it has not written it yet)."""
    deadline = time.monotonic() + HOLDER_WAIT_S
    while True:
        try:
            data = json.loads(os.pread(fd, 4096, 0).decode("utf-8"))
        except (OSError, ValueError):
            data = None
        if isinstance(data, dict) or time.monotonic() >= deadline:
            return data if isinstance(data, dict) else {}
        time.sleep(POLL_S)


def _in_use(folder: Path, holder: dict[str, object]) -> InUse:
    """The one-line refusal naming the holder."""
    if holder:
        who = (
            f"`{holder.get('command', '?')}` (PID {holder.get('pid', '?')} on "
            f"{holder.get('host', '?')}, since {holder.get('since', '?')})"
        )
    else:
        who = "another command"
    return InUse(f"{folder} is in use by {who}", "wait for it to finish, or stop it")


def _write_holder(fd: int, command: str) -> None:
    text = json.dumps(
        {"pid": os.getpid(), "host": socket.gethostname(), "command": command, "since": _now()}
    )
    os.ftruncate(fd, 0)
    os.pwrite(fd, (text + "\n").encode("utf-8"), 0)


def _acquire(folder: Path, command: str, wait_s: float) -> int:
    path = folder / LOCK_FILE
    deadline = time.monotonic() + wait_s
    while True:
        fd = _open(path)
        try:
            if _try_lock(fd, path):
                if _is_current(fd, path):
                    try:
                        _write_holder(fd, command)
                    except OSError as error:  # a full disk: no lock file left behind
                        with contextlib.suppress(OSError):
                            path.unlink(missing_ok=True)
                        raise fs_error(error, path) from error
                    return fd
            elif time.monotonic() >= deadline:
                raise _in_use(folder, _read_holder(fd))
            else:
                time.sleep(POLL_S)
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)  # busy, or locked after its holder removed it: try the file there now


def _release(folder: Path, hold: _Hold) -> None:
    path = folder / LOCK_FILE
    try:
        if _is_current(hold.fd, path):  # only our own file; a waiter locking it then retries
            path.unlink()
    except OSError:
        pass  # a read-only folder keeps the file; the kernel still drops the lock below
    os.close(hold.fd)
    _remove_empty(hold.created)


def _make(folder: Path) -> tuple[Path, ...]:
    """Make ``folder`` and its missing parents; the ones this call made, deepest first."""
    missing = []
    for path in (folder, *folder.parents):
        if path.exists():
            break
        missing.append(path)
    try:
        folder.mkdir(parents=True)
    except FileExistsError:  # another process made it meanwhile
        return ()
    return tuple(missing)


def _remove_empty(made: tuple[Path, ...]) -> None:
    for path in made:
        try:
            path.rmdir()
        except OSError:
            return  # not empty: the command left its work there


@contextmanager
def locked(
    folder: Path | str, command: str, *, wait_s: float = 0.0, create: bool = False
) -> Iterator[None]:
    """Hold ``folder``'s lock for the block, as ``command`` (e.g. ``rig capture``).

    Another holder makes this raise :class:`InUse` at once, or after ``wait_s`` seconds of
    waiting for it. ``create`` makes a missing folder and its missing parents (removed again
    if left empty); otherwise a missing folder is a RigError."""
    folder = Path(folder).expanduser().absolute()
    key = folder.resolve()  # one hold whichever link or relative path names the folder
    holds = _holds()
    hold = holds.get(key)
    if hold is not None:
        hold.depth += 1
        try:
            yield
        finally:
            hold.depth -= 1
        return
    created = _make(folder) if create and not folder.exists() else ()
    try:
        hold = _Hold(_acquire(folder, command, wait_s), 1, created)
    except BaseException:
        _remove_empty(created)  # never raises: the refusal matters, not this tidying
        raise
    holds[key] = hold
    try:
        yield
    finally:
        del holds[key]
        _release(folder, hold)


def enclosing_session(path: Path | str) -> Path | None:
    """The session folder ``path`` is in (or is), if any."""
    path = Path(path).expanduser().absolute()
    for folder in (path, *path.parents):
        if (folder / SESSION_FILE).is_file():
            return folder
    return None


@contextmanager
def output_lock(path: Path | str, command: str) -> Iterator[None]:
    """Hold the lock of the session ``path`` is written into; nothing outside a session."""
    session = enclosing_session(path)
    if session is None:
        yield
        return
    with locked(session, command):
        yield
