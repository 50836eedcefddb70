"""`rig check-chart` on a session without a chart, and on a session another writer holds."""

from __future__ import annotations

from pathlib import Path

import pytest
from lockholder import hold, release_all
from simrig import PROFILE

from rig.cli import main


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cc") / "s"
    assert main(["capture", "--yes", "--profile", str(PROFILE), "--out", str(out)]) == 0
    return out


def test_a_session_without_a_chart_is_one_error(
    session: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["check-chart", str(session), "--view", "0"]) != 0
    assert "no classic24 colour chart found in view(s) [0]" in capsys.readouterr().err


def test_an_unknown_view_names_the_views(
    session: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["check-chart", str(session), "--view", "99"]) != 0
    assert "has no decoded frames of view(s) [99]" in capsys.readouterr().err


def test_a_held_session_is_refused(session: Path, capsys: pytest.CaptureFixture[str]) -> None:
    hold(session)
    try:
        assert main(["check-chart", str(session)]) != 0
    finally:
        release_all()
    assert "is in use by `rig capture`" in capsys.readouterr().err
