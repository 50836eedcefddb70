"""The pip command that adds an optional extra to this installation of spectral-rig.

spectral-rig is installed from a git checkout (editable or not), from a git URL or an archive,
and perhaps one day from an index; ``pip install 'spectral-rig[gphoto2]'`` works only in the
last case. pip records where a distribution came from in its ``direct_url.json`` (PEP 610),
so the hint is built from that record, for the interpreter that is running.
"""

from __future__ import annotations

import json
import shlex
import sys
from importlib import metadata
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlparse
from urllib.request import url2pathname

DISTRIBUTION = "spectral-rig"
CHECKOUT = Path(__file__).resolve().parents[1]  # the folder holding core/ and pyproject.toml


def install_command(extra: str) -> str:
    """One shell command that installs ``extra`` the way spectral-rig itself was installed."""
    pip = f"{shlex.quote(sys.executable)} -m pip install"
    origin = installed_from()
    if origin is None:
        if (CHECKOUT / "pyproject.toml").is_file():  # run from a checkout, not installed
            return f"{pip} -e {shlex.quote(f'{CHECKOUT}[{extra}]')}"
        return f"{pip} {shlex.quote(f'{DISTRIBUTION}[{extra}]')}"
    return f"{pip} {requirement(origin, extra)}"


def installed_from() -> dict[str, Any] | None:
    """The distribution's ``direct_url.json`` record; ``{}`` when it came from an index,
    None when spectral-rig is not installed at all."""
    try:
        distribution = metadata.distribution(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return None
    text = distribution.read_text("direct_url.json")
    if not text:
        return {}
    try:
        record = json.loads(text)
    except ValueError:
        return {}
    return record if isinstance(record, dict) else {}


def requirement(origin: dict[str, Any], extra: str) -> str:
    """pip's arguments for ``extra`` given a ``direct_url.json`` record (shell-quoted)."""
    url = str(origin.get("url", ""))
    named = f"{DISTRIBUTION}[{extra}]"
    if not url:
        return shlex.quote(named)
    if "dir_info" in origin and url.startswith("file:"):
        folder = url2pathname(unquote(urlparse(url).path))
        editable = bool(origin["dir_info"].get("editable"))
        return ("-e " if editable else "") + shlex.quote(f"{folder}[{extra}]")
    vcs = origin.get("vcs_info")
    if isinstance(vcs, dict):
        revision = vcs.get("requested_revision")
        source = f"{vcs.get('vcs', 'git')}+{url}" + (f"@{revision}" if revision else "")
        return shlex.quote(f"{named} @ {source}")
    return shlex.quote(f"{named} @ {url}")
