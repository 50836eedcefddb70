"""Install hints follow how spectral-rig was installed (it is not on PyPI: a checkout's hint
must name the checkout)."""

from __future__ import annotations

import shlex
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

import pytest

from core import install
from core.errors import MissingDependencyError
from core.install import install_command, requirement


def test_this_installation_gets_a_hint_that_names_a_folder_declaring_the_extra() -> None:
    tomllib = pytest.importorskip("tomllib")
    words = shlex.split(install_command("gphoto2"))
    assert words[:4] == [sys.executable, "-m", "pip", "install"]
    origin = install.installed_from()
    if origin is not None and "url" not in origin:
        pytest.skip("installed from an index: the plain name is right")
    target = words[-1]
    assert target.endswith("[gphoto2]")
    folder = Path(target[: -len("[gphoto2]")])
    project = tomllib.loads((folder / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert project["name"] == "spectral-rig"
    assert "gphoto2" in project["optional-dependencies"]
    if origin is None or origin.get("dir_info", {}).get("editable"):
        assert words[4] == "-e"


@pytest.mark.parametrize(
    ("origin", "expected"),
    [
        ({"url": "file:///home/me/spectral-rig", "dir_info": {"editable": True}},
         "-e '/home/me/spectral-rig[tuya]'"),
        ({"url": "file:///home/me/my%20rig", "dir_info": {}}, "'/home/me/my rig[tuya]'"),
        ({"url": "https://github.com/lab/spectral-rig.git",
          "vcs_info": {"vcs": "git", "commit_id": "0" * 40, "requested_revision": "v0.1"}},
         "'spectral-rig[tuya] @ git+https://github.com/lab/spectral-rig.git@v0.1'"),
        ({"url": "https://example.org/spectral-rig-0.1.tar.gz", "archive_info": {}},
         "'spectral-rig[tuya] @ https://example.org/spectral-rig-0.1.tar.gz'"),
        ({}, "'spectral-rig[tuya]'"),
    ],
)
def test_requirement_from_each_kind_of_direct_url_record(
    origin: dict[str, Any], expected: str
) -> None:
    assert requirement(origin, "tuya") == expected


def test_without_an_installed_distribution_the_checkout_is_named(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def missing(name: str) -> None:
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(install.metadata, "distribution", missing)
    checkout = Path(install.__file__).resolve().parents[1]
    assert install_command("seabreeze").endswith(f"-e {shlex.quote(f'{checkout}[seabreeze]')}")


def test_missing_dependency_error_carries_the_hint() -> None:
    error = MissingDependencyError("gphoto2", "gphoto2", "needed for tethered cameras")
    assert str(error).endswith(f"install it with `{install_command('gphoto2')}`")
