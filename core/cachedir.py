"""The user's cache folder, chosen by the standard variables, for the libraries that keep one.

matplotlib (its font list) and numba (compiled kernels, when the install's own folder is not
writable) create ``~/.config/matplotlib``, ``~/.cache/matplotlib`` or ``~/.cache/numba``
themselves, with every missing parent: with ``HOME`` pointing at a missing folder even
`rig calibrate list` would create ``$HOME``. :func:`direct_library_caches`, called as a command
starts (before either library is imported), points them at :func:`user_cache_dir` instead
whenever their own choice would create a folder the user does not have; a variable the user
set is left alone.
"""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import MutableMapping
from pathlib import Path

APP = "spectral-rig"


def _usable(folder: Path) -> bool:
    return folder.is_dir() and os.access(folder, os.W_OK | os.X_OK)


def _private_temp() -> Path:
    """A folder of this user's in the temporary directory, kept between commands; a fresh one
    when the name is taken by someone else (or is a link)."""
    folder = Path(tempfile.gettempdir()) / f"{APP}-cache-{os.getuid()}"
    try:
        folder.mkdir(mode=0o700)
    except FileExistsError:
        pass
    except OSError:
        return Path(tempfile.mkdtemp(prefix=f"{APP}-cache-"))
    info = os.lstat(folder)
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid() or info.st_mode & 0o077:
        return Path(tempfile.mkdtemp(prefix=f"{APP}-cache-"))
    return folder


def user_cache_dir(env: MutableMapping[str, str] | None = None) -> Path:
    """``$XDG_CACHE_HOME`` (an absolute path), else ``~/.cache`` when it exists and is
    writable, else a private folder in the temporary directory."""
    env = os.environ if env is None else env
    xdg = env.get("XDG_CACHE_HOME", "")
    if os.path.isabs(xdg):
        return Path(xdg)
    home = env.get("HOME") or os.path.expanduser("~")
    cache = Path(home) / ".cache"
    return cache if _usable(cache) else _private_temp()


def _home_base(env: MutableMapping[str, str], variable: str, default: str) -> Path:
    value = env.get(variable, "")
    home = Path(env.get("HOME", "~")).expanduser()
    return Path(value) if os.path.isabs(value) else home / default


def direct_library_caches(env: MutableMapping[str, str] | None = None) -> None:
    """Set ``MPLCONFIGDIR`` and ``NUMBA_CACHE_DIR`` (when unset) to folders under
    :func:`user_cache_dir` where the libraries' own choice would create missing folders."""
    env = os.environ if env is None else env
    config = _home_base(env, "XDG_CONFIG_HOME", ".config")
    cache = _home_base(env, "XDG_CACHE_HOME", ".cache")
    if "MPLCONFIGDIR" not in env and not (_usable(config) and _usable(cache)):
        env["MPLCONFIGDIR"] = str(user_cache_dir(env) / "matplotlib")
    if "NUMBA_CACHE_DIR" not in env and not _usable(cache):
        env["NUMBA_CACHE_DIR"] = str(user_cache_dir(env) / "numba")
