"""Which sessions a batch runs: paths on the command line and in ``--list`` files."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from core.errors import RigError


def read_list(path: Path) -> list[Path]:
    """One session folder per line; blank lines and ``#`` comments are skipped; relative
    paths are relative to the list file's folder."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise RigError(f"cannot read --list {path}: {error}", "give a text file") from error
    lines = (line.split("#", 1)[0].strip() for line in text.splitlines())
    return [path.parent / line for line in lines if line]


def collect(paths: Sequence[Path], list_file: Path | None) -> list[Path]:
    """Absolute, de-duplicated session paths in the order given. A path that is no session is
    kept: its task fails and the batch reports it with the others."""
    given = [*paths, *(read_list(list_file) if list_file is not None else [])]
    if not given:
        raise RigError("no session given", "name session folders or a --list file")
    unique = dict.fromkeys(Path(p).expanduser().resolve() for p in given)
    return list(unique)
