"""Checks on output paths given on the command line, before any work is done.

Writing to ``--out x.pdf`` when ``x.pdf`` is a folder, or to a folder path that is an existing
file (or lies under one), would otherwise end in an ``OSError`` deep in a writer, after the
work, as an internal error. Each check names the flag and the fix in one line.
"""

from __future__ import annotations

from pathlib import Path

from core.errors import RigError


def _file_ancestor(path: Path) -> Path | None:
    """The first existing ancestor of ``path`` that is not a folder (nothing can go under it)."""
    for parent in path.parents:
        if parent.exists():
            return None if parent.is_dir() else parent
    return None


def output_file(path: Path, flag: str) -> Path:
    """``path`` as a file to (over)write: not a folder, not under a file."""
    path = Path(path).expanduser()
    if path.is_dir():
        raise RigError(f"{flag} {path} is a folder", f"give a file name for {flag}")
    blocker = _file_ancestor(path)
    if blocker is not None:
        raise RigError(
            f"{flag} {path}: {blocker} is a file, not a folder", f"choose another path for {flag}"
        )
    return path


def output_dir(path: Path, flag: str) -> Path:
    """``path`` as a folder to create or fill: not an existing file, not under a file."""
    path = Path(path).expanduser()
    if path.exists() and not path.is_dir():
        raise RigError(
            f"{flag} {path} is an existing file, not a folder", f"give a folder path for {flag}"
        )
    blocker = _file_ancestor(path)
    if blocker is not None:
        raise RigError(
            f"{flag} {path}: {blocker} is a file, not a folder", f"choose another path for {flag}"
        )
    return path
