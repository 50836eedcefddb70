"""`rig --help`, argument errors and `rig session info` start at once: the parser and those
commands load none of the heavy libraries (checked by module, never by time)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from simrig import PROFILE

from rig.cli import COMMANDS, main

REPO = Path(__file__).resolve().parents[2]
HEAVY = ("pycolmap", "numba", "cv2", "colour", "matplotlib", "scipy", "trimesh", "rawpy")


def heavy_loaded(code: str) -> list[str]:
    """The heavy packages a fresh interpreter has loaded after running ``code``."""
    probe = f"{code}\nimport sys\nprint(*sorted({{m.split('.')[0] for m in sys.modules}}))"
    proc = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    loaded = proc.stdout.split()
    assert loaded, proc.stderr
    return [m for m in HEAVY if m in loaded]


def test_building_the_parser_loads_no_heavy_library() -> None:
    assert heavy_loaded("from rig.cli import build_parser\nbuild_parser()") == []


def test_an_argument_error_loads_no_heavy_library() -> None:
    code = (
        "from rig.cli import main\n"
        "try:\n"
        "    main(['capture', '--bogus'])\n"
        "except SystemExit as stop:\n"
        "    assert stop.code == 2\n"
    )
    assert heavy_loaded(code) == []


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_has_help(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        main([command, "--help"])
    assert stop.value.code == 0
    assert f"usage: rig {command}" in capsys.readouterr().out


def test_session_info_loads_no_heavy_library(tmp_path: Path) -> None:
    session = tmp_path / "s"
    assert main(["capture", "--yes", "--profile", str(PROFILE), "--out", str(session)]) == 0
    code = f"from rig.cli import main\nassert main(['session', 'info', {str(session)!r}]) == 0"
    assert heavy_loaded(code) == []


def test_parser_constants_match_the_libraries_they_repeat() -> None:
    from calibration import defaults
    from reconstruct.poses.board import spec
    from reconstruct.stages import resolution
    from rig import cliargs, profile, wizard
    from rig.commands import board, reconstruct, view
    from rig.view import colour

    assert board.PAPER_SIZES == tuple(spec.PAPER_SIZES_M)
    assert board.DEFAULT_DICTIONARY == spec.DEFAULT_DICTIONARY
    assert board.DEFAULT_SQUARES == spec.DEFAULT_SQUARES
    assert board.DEFAULT_MARKER_RATIO == spec.DEFAULT_MARKER_RATIO
    assert view.DEFAULT_ILLUMINANTS == colour.DEFAULT_ILLUMINANTS
    assert list(wizard.BUILTIN_CAMERAS) == defaults.camera_names()
    assert cliargs.MAX_VIEWS == profile.MAX_VIEWS
    assert reconstruct.DETAILS == tuple(resolution.MAX_SIDE)
