"""core.fserrors (one line per file-system failure), core.files' atomic writes on failure and
core.cachedir (the cache folder the libraries are sent to)."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from core.cachedir import direct_library_caches, user_cache_dir
from core.errors import RigError
from core.files import atomic_output, write_bytes_atomically
from core.fserrors import fs_error, underlying_fs_error


def test_a_full_disk_names_the_path_given_when_the_error_names_none(tmp_path: Path) -> None:
    error = fs_error(OSError(errno.ENOSPC, "No space left on device"), tmp_path / "a.npy")
    assert str(error).startswith(f"no space left on the disk holding {tmp_path / 'a.npy'} — ")


def test_a_file_in_the_way_is_named_not_the_path_under_it(tmp_path: Path) -> None:
    (tmp_path / "recon").write_text("x")
    error = fs_error(OSError(errno.ENOTDIR, "Not a directory", str(tmp_path / "recon/a/b")))
    assert f"{tmp_path / 'recon'} is a file where a folder should be" in str(error)
    exists = fs_error(OSError(errno.EEXIST, "File exists", str(tmp_path / "recon")))
    assert "is a file where a folder should be" in str(exists)


def test_an_unknown_failure_keeps_the_systems_words(tmp_path: Path) -> None:
    error = fs_error(OSError(errno.EXDEV, "Invalid cross-device link", str(tmp_path)))
    assert "Invalid cross-device link" in str(error) and str(tmp_path) in str(error)


def test_the_failure_behind_a_writers_own_error_is_found() -> None:
    try:
        try:
            raise OSError(errno.ENOSPC, "No space left on device")
        except OSError:
            raise ValueError("Error -2 while flushing") from None
    except ValueError as error:
        assert underlying_fs_error(error) is None  # `from None`: not raised while handling it
    try:
        try:
            raise OSError(errno.ENOSPC, "No space left on device")
        except OSError:
            raise ValueError("Error -2 while flushing")  # noqa: B904 (as zlib does)
    except ValueError as error:
        cause = underlying_fs_error(error)
        assert cause is not None and cause.errno == errno.ENOSPC


def test_a_failed_atomic_write_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "b.pdf"
    path.write_bytes(b"old")
    with pytest.raises(RigError, match=r"no space left on the disk holding .*b\.pdf"):
        with atomic_output(path) as tmp:
            tmp.write_bytes(b"half")
            raise OSError(errno.ENOSPC, "No space left on device")
    assert path.read_bytes() == b"old" and sorted(tmp_path.iterdir()) == [path]
    write_bytes_atomically(path, b"new")
    assert path.read_bytes() == b"new" and sorted(tmp_path.iterdir()) == [path]


def test_library_caches_go_to_the_users_cache_folder(tmp_path: Path) -> None:
    missing = {"HOME": str(tmp_path / "nohome")}
    direct_library_caches(missing)
    assert not (tmp_path / "nohome").exists()
    assert Path(missing["MPLCONFIGDIR"]).parent == user_cache_dir({"HOME": str(tmp_path / "x")})
    assert missing["NUMBA_CACHE_DIR"].endswith("numba")
    home = tmp_path / "home"
    (home / ".cache").mkdir(parents=True)
    (home / ".config").mkdir()
    present = {"HOME": str(home)}
    direct_library_caches(present)
    assert present == {"HOME": str(home)}  # the libraries' own choice creates nothing new
    assert user_cache_dir(present) == home / ".cache"
    chosen = {"HOME": str(tmp_path / "nohome"), "MPLCONFIGDIR": "/mine", "XDG_CACHE_HOME": "/c"}
    direct_library_caches(chosen)
    assert chosen["MPLCONFIGDIR"] == "/mine" and chosen["NUMBA_CACHE_DIR"] == "/c/numba"


def test_the_temporary_cache_folder_is_private(tmp_path: Path) -> None:
    folder = user_cache_dir({"HOME": str(tmp_path / "nohome")})
    info = os.lstat(folder)
    assert info.st_uid == os.getuid() and not info.st_mode & 0o077
