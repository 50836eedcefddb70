"""Free projector placements: camera and projector moved alternately. The plan tags every
frame with its placement, asks for the projector move only when the placement changes, and
the manifest records ``projector_placement`` for reconstruct.initial_mesh.procam."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from fakes import PROFILE, fake_rig
from rich.console import Console

from core.errors import RigError
from core.session import Session
from rig.capture import run_capture
from rig.plans import MoveProjector, MoveTo, capture_plan, frame_list
from rig.profile import Profile, ProjectorPlacements, parse_profile


def _profile(**projector: Any) -> Profile:
    data = {
        **PROFILE,
        "devices": {**PROFILE["devices"], "projector": {"driver": "sim"}},
        "plan": {"views": 6, "illuminations": ["A", "B"], "projector": projector},
    }
    return parse_profile(data, "fake.yaml")


def test_frames_carry_their_placement_and_moves_alternate() -> None:
    plan = _profile(placements=3).plan
    assert plan.projector == ProjectorPlacements(3, 2)
    frames = frame_list(plan)
    assert [f.placement for f in frames] == [v // 2 for v in range(6) for _ in range(2)]
    moves = [m for m in capture_plan(frames, set(), 6, 3) if isinstance(m, MoveProjector | MoveTo)]
    assert moves == [
        MoveProjector(0, 3),
        MoveTo(0, 6),
        MoveTo(1, 6),
        MoveProjector(1, 3),
        MoveTo(2, 6),
        MoveTo(3, 6),
        MoveProjector(2, 3),
        MoveTo(4, 6),
        MoveTo(5, 6),
    ]
    # resumed inside placement 1: the projector is asked for again before the camera
    resumed = list(capture_plan(frames, set(range(7)), 6, 3))
    assert resumed[:2] == [MoveProjector(1, 3), MoveTo(3, 6)]


@pytest.mark.parametrize(
    ("projector", "expected"),
    [
        ({"placements": 4}, "placements x views_per_placement"),
        ({"placements": 2, "views_per_placement": 2}, "views_per_placement"),
        ({"placements": 0}, "plan.projector.placements"),
        ({"placements": 2, "turns": 1}, "plan.projector.turns"),
    ],
)
def test_bad_placements_are_refused(projector: dict[str, Any], expected: str) -> None:
    with pytest.raises(RigError, match=expected):
        _profile(**projector)


def test_placements_need_a_projector() -> None:
    data = {**PROFILE, "plan": {"views": 4, "projector": {"placements": 2}}}
    with pytest.raises(RigError, match="needs a projector"):
        parse_profile(data, "fake.yaml")


def test_person_is_asked_to_move_projector_then_camera(tmp_path: Path) -> None:
    asked: list[str] = []

    def ask(text: str) -> str:
        asked.append(text)
        return ""

    out = run_capture(
        _profile(placements=2),
        tmp_path / "s",
        ask=ask,
        open_rig=fake_rig(),
        console=Console(quiet=True),
    )
    assert [a.split(" (leave")[0].split(" (coverage")[0] for a in asked] == [
        "Move the projector to placement 1/2",
        "Move the camera (not the projector) to view 0 (1/6)",
        "Move the camera (not the projector) to view 1 (2/6)",
        "Move the camera (not the projector) to view 2 (3/6)",
        "Move the projector to placement 2/2",
        "Move the camera (not the projector) to view 3 (4/6)",
        "Move the camera (not the projector) to view 4 (5/6)",
        "Move the camera (not the projector) to view 5 (6/6)",
    ]
    session = Session.open(out)
    assert {(f.view, f.extra["projector_placement"]) for f in session.frames} == {
        (v, v // 3) for v in range(6)
    }
    assert session.info.plan.projector_placements == {
        "placements": 2,
        "views_per_placement": 3,
    }
