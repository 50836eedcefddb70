"""The one mapping from a failed file-system call to the line a user reads.

A full disk, a read-only or foreign-owned folder, or a file where a folder should be reaches
the code as an ``OSError`` from deep inside a writer (NumPy, matplotlib, a copy). The CLI's
error handler, the reconstruction's stage runner and the atomic writers of :mod:`core.files`
turn it into a :class:`RigError` here, so every such failure is one line naming the path and
the fix, whatever wrote the file.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path

from core.errors import RigError

# errno -> (what happened to PATH, the fix)
_MESSAGES: dict[int, tuple[str, str]] = {
    errno.ENOSPC: (
        "no space left on the disk holding {path}",
        "free space on that disk (or write to another one) and run the command again",
    ),
    errno.EDQUOT: (
        "the disk quota is exceeded writing {path}",
        "free space within your quota (or write to another disk) and run the command again",
    ),
    errno.EROFS: (
        "{path} is on a read-only file system",
        "copy the folder to a writable disk (or remount it read-write) and run the command "
        "there",
    ),
    errno.EACCES: (
        "permission denied for {path}",
        "make it writable for you (chmod/chown) or choose a folder you own",
    ),
    errno.EPERM: (
        "the operation is not permitted on {path}",
        "make it writable for you (chmod/chown, or clear its immutable flag) or choose a "
        "folder you own",
    ),
    errno.ENOTDIR: (
        "{path} is a file where a folder should be",
        "move that file away (or choose another path) and run the command again",
    ),
    errno.EISDIR: (
        "{path} is a folder where a file should be",
        "move that folder away (or choose another path) and run the command again",
    ),
    errno.EEXIST: (
        "{path} is in the way: it exists and is not what the command writes there",
        "move it away (or choose another path) and run the command again",
    ),
    errno.ENOENT: (
        "{path} does not exist (or was removed while the command ran)",
        "check the path and run the command again",
    ),
    errno.ELOOP: (
        "{path} is a symbolic link the command will not follow",
        "replace the link with the real file or folder",
    ),
    errno.ENAMETOOLONG: ("the path {path} is too long", "choose a shorter path"),
    errno.EIO: (
        "input/output error on {path}",
        "the disk may be failing or unplugged: check it, then copy the data to a healthy disk",
    ),
    errno.EMFILE: (
        "too many open files while using {path}",
        "raise the limit (`ulimit -n 4096`) and run the command again",
    ),
}
ERRNOS = frozenset(_MESSAGES)


def _blocker(path: Path) -> Path:
    """For ENOTDIR: the first existing ancestor of ``path`` that is not a folder."""
    for parent in reversed(path.parents):
        if parent.exists() and not parent.is_dir():
            return parent
    return path


def fs_error(error: OSError, path: str | os.PathLike[str] | None = None) -> RigError:
    """A :class:`RigError` for ``error``: the path is the error's own when it names one, else
    ``path`` (what the caller was writing). Errors of no known kind keep the system's words."""
    named = error.filename if error.filename not in (None, "") else path
    target = Path(os.fsdecode(named)) if named is not None else None
    shown = str(target) if target is not None else "the files being written"
    code = error.errno
    if code == errno.ENOTDIR and target is not None:
        shown = str(_blocker(target))
    elif code == errno.EEXIST and target is not None and target.exists():
        code = errno.ENOTDIR if not target.is_dir() else code
    if code in _MESSAGES:
        problem, fix = _MESSAGES[code]
        return RigError(problem.format(path=shown), fix)
    reason = error.strerror or str(error)
    return RigError(
        f"cannot write or read {shown} ({reason})",
        "check the free space and the permissions of that disk, then run the command again",
    )


def is_fs_error(error: OSError) -> bool:
    """Whether ``error`` is a file-system failure :func:`fs_error` describes (not, say, a
    network timeout, which is also an ``OSError``)."""
    return error.errno in ERRNOS or bool(error.filename)


def underlying_fs_error(error: BaseException) -> OSError | None:
    """The file-system failure behind ``error``: itself, or one it was raised while handling
    (a writer's clean-up that failed in turn, as matplotlib's PDF stream does on a full
    disk); None when there is none."""
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        if isinstance(current, OSError) and is_fs_error(current):
            return current
        seen.add(id(current))
        hidden = current.__suppress_context__  # `raise ... from None`: not a consequence
        current = current.__cause__ or (None if hidden else current.__context__)
    return None
