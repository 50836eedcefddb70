"""Capture with a marker board: the sim rig stands on it, every view's first frame is checked
for it, and the exposure check reports its contrast."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from fakes import PROFILE, fake_rig
from rich.console import Console

from core.session import Session
from reconstruct.poses.board import BoardSpec, detect_board
from rig.capture import run_capture
from rig.capture.board_check import board_image
from rig.capture.frames import read_raw
from rig.profile import load_profile, parse_profile

SIM_BOARD = Path(__file__).with_name("sim-board.yaml")


def test_sim_capture_on_a_board_sees_it_in_every_view(tmp_path: Path) -> None:
    profile = load_profile(SIM_BOARD)
    assert isinstance(profile.board, BoardSpec) and profile.board.paper == "A3"
    out = run_capture(profile, tmp_path / "s", yes=True, console=Console(file=None, quiet=True))
    session = Session.open(out)
    assert BoardSpec.from_dict(dict(session.info.board or {})) == profile.board
    checks = session.info.board_checks
    assert sorted(checks) == [0, 1, 2]
    for view, check in checks.items():
        assert check["corners"] >= 6 and check["contrast"] > 0.2, (view, check)
        frame = next(f for f in session.frames if f.frame == check["frame"])
        assert frame.view == view and frame.illumination == "LED2"  # the view's first lit frame
        look = board_image(read_raw(out / frame.path), check["binning"])
        assert detect_board(look, profile.board).n_corners == check["corners"]
    for label in ("LED2", "LED3"):
        assert session.info.exposure_checks[label]["board_contrast"] > 0.2


def test_dim_board_gets_an_exposure_hint(tmp_path: Path) -> None:
    data = yaml.safe_load(SIM_BOARD.read_text())
    data["plan"]["views"] = 1
    data["camera_settings"]["exposure_s"] /= 8  # three stops under
    console = Console(record=True, width=250)
    out = run_capture(parse_profile(data, "dim.yaml"), tmp_path / "s", yes=True, console=console)
    checks = Session.open(out).info.exposure_checks
    assert all(c["board_contrast"] < 0.2 for c in checks.values())
    text = console.export_text()
    assert "lengthen the exposure" in text
    assert "board's paper/ink contrast is only" in text or "board corners found" in text


def test_capture_warns_when_the_board_is_not_in_view(tmp_path: Path) -> None:
    data = {**PROFILE, "board": BoardSpec.fit_paper("A4").to_dict()}
    console = Console(record=True, width=200)
    out = run_capture(
        parse_profile(data, "fake.yaml"),
        tmp_path / "s",
        yes=True,
        console=console,
        open_rig=fake_rig(),
    )
    text = console.export_text()
    assert "view 0: only 0 board corners found" in text and "view 3:" in text
    session = Session.open(out)
    checks = session.info.board_checks
    assert all(c["corners"] == 0 and c["contrast"] == 0.0 for c in checks.values())
    lit = {f.frame for f in session.frames if f.illumination == "A"}  # not the ambient frames
    assert {c["frame"] for c in checks.values()} == lit


@pytest.mark.parametrize("bad", [{"squares": [1, 7]}, {"square_length_m": None}, "A3"])
def test_bad_board_section_is_refused(bad: object) -> None:
    from core.errors import RigError

    board = BoardSpec.fit_paper("A3").to_dict()
    section = {**board, **bad} if isinstance(bad, dict) else bad
    if isinstance(section, dict):
        section = {k: v for k, v in section.items() if v is not None}
    with pytest.raises(RigError, match="fake.yaml"):
        parse_profile({**PROFILE, "board": section}, "fake.yaml")
