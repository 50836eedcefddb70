"""session.yaml read as a typed SessionInfo: every key capture writes, the profile snapshot as
the fallback for camera, board and distances, and one error naming the file and the key."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from core.errors import RigError
from core.session import Session
from core.session_info import CameraIntrinsics, KnownDistance, SessionInfo

CAPTURED: dict[str, Any] = {
    "format": 1,
    "created": "2026-01-01T00:00:00+00:00",
    "profile_name": "sim",
    "profile_source": "profiles/sim.yaml",
    "profile": {"board": {"squares": [5, 7]}},
    "seed": 3,
    "plan": {
        "views": 4,
        "illuminations": ["LED1", "LED2"],
        "ambient": True,
        "structured_light": False,
        "frames": 12,
        "projector_size": None,
        "projector_placements": None,
    },
    "light_mount": {"type": "plate", "offset_m": [0.05, 0, 0], "diameter_m": 0.06},
    "known_distances": [{"views": [0, 2], "metres": 0.5}],
    "known_lengths": {"light_offset_m": 0.05},
    "calibration": {"store": "default", "snapshot": "calibration", "camera": "C",
                    "lights": {"LED1": "led-1"}},
    "software": {"numpy": "2.0"},
    "devices": {"camera": {"driver": "sim"}, "projector": {"resolution": [64, 48]}},
    "notes": "",
    "runs": [{"status": "complete"}],
    "board_checks": {0: {"corners": 12}},
    "ground_truth": "ground_truth",
}


def test_a_captured_session_yaml_reads_as_typed_fields() -> None:
    info = SessionInfo.from_mapping(CAPTURED)
    assert info.plan.views == 4 and info.plan.frames == 12
    assert info.plan.illuminations == ("LED1", "LED2")
    assert info.projector_size == (64, 48)  # no plan size: the projector's recorded one
    assert info.light_offset_m == (0.05, 0.0, 0.0) and info.light_diameter_m == 0.06
    assert info.known_distances == (KnownDistance((0, 2), 0.5),)
    assert info.calibration.camera == "C" and info.calibration.lights == {"LED1": "led-1"}
    assert info.board == {"squares": [5, 7]}  # from the profile snapshot
    assert info.board_checks[0]["corners"] == 12
    assert info.runs[0]["status"] == "complete" and info.ground_truth == "ground_truth"
    assert info.intrinsics is None and info.poses is None


def test_an_empty_or_foreign_session_yaml_has_defaults() -> None:
    for data in (None, {}, {"rig": "synthetic"}):
        info = SessionInfo.from_mapping(data)
        assert info.plan.views is None and info.plan.illuminations is None
        assert info.calibration.camera is None and info.known_distances == ()
        assert info.projector_size is None and info.light_offset_m is None
        assert info.light_diameter_m == 0.0  # a point light


def test_the_profile_snapshot_gives_intrinsics_and_camera_pairs() -> None:
    info = SessionInfo.from_mapping({"profile": {
        "camera": {"intrinsics": {"model": "PINHOLE", "width": 4, "height": 2,
                                  "params": [3, 3, 2, 1]}},
        "known_distances": {"camera_pairs": [{"views": [0, 1], "metres": 2}]},
    }})
    assert info.intrinsics == CameraIntrinsics("PINHOLE", 4, 2, (3.0, 3.0, 2.0, 1.0))
    assert info.known_distances == (KnownDistance((0, 1), 2.0),)


@pytest.mark.parametrize(
    ("data", "key"),
    [
        ([1, 2], None),
        ({"plan": "four"}, "plan"),
        ({"plan": {"views": 0}}, "plan.views"),
        ({"plan": {"views": "4"}}, "plan.views"),
        ({"plan": {"illuminations": "LED1"}}, "plan.illuminations"),
        ({"plan": {"projector_size": [64]}}, "plan.projector_size"),
        ({"light_mount": {"offset_m": [0, "x", 0]}}, "light_mount.offset_m"),
        ({"light_mount": {"diameter_m": "6 cm"}}, "light_mount.diameter_m"),
        ({"light_mount": {"diameter_m": -0.06}}, "light_mount.diameter_m"),
        ({"calibration": {"lights": ["LED1"]}}, "calibration.lights"),
        ({"intrinsics": {"model": "PINHOLE"}}, "intrinsics"),
        ({"profile": {"camera": {"intrinsics": {"model": "PINHOLE", "width": "w",
                                                "height": 2, "params": []}}}},
         "profile.camera.intrinsics"),
        ({"known_distances": [{"views": [0]}]}, "known_distances[0]"),
        ({"known_distances": "0-1: 2 m"}, "known_distances"),
        ({"board": [5, 7]}, "board"),
        ({"devices": {"camera": "sim"}}, "devices.camera"),
        ({"runs": "complete"}, "runs"),
        ({"seed": 1.5}, "seed"),
        ({"board_checks": {"first": {}}}, "board_checks.first"),
    ],
)
def test_a_bad_value_names_the_file_and_the_key(data: Any, key: str | None) -> None:
    with pytest.raises(RigError) as error:
        SessionInfo.from_mapping(data, "s/session.yaml")
    assert error.value.problem.startswith("s/session.yaml")
    assert "\n" not in error.value.problem
    if key is not None:
        assert f"`{key}`" in error.value.problem


def test_opening_a_session_with_a_bad_value_fails_at_once(tmp_path: Path) -> None:
    (tmp_path / "session.yaml").write_text(yaml.safe_dump({"plan": {"views": -2}}))
    with pytest.raises(RigError, match=r"session\.yaml: `plan\.views` is -2"):
        Session.open(tmp_path)


def test_flat_field_choice_is_typed_and_optional() -> None:
    info = SessionInfo.from_mapping(
        {"calibration": {"flat_field": {"entry": "flat/cam", "version": 2, "method": "lensfun"}}}
    )
    assert info.calibration.flat_field is not None
    assert (info.calibration.flat_field.entry, info.calibration.flat_field.version) == (
        "flat/cam",
        2,
    )
    assert SessionInfo.from_mapping({"calibration": {"flat_field": None}}).calibration.flat_field \
        is None
    for bad in ("flat/cam", {"entry": "x"}, {"entry": "x", "version": 0}):
        with pytest.raises(RigError, match="calibration.flat_field"):
            SessionInfo.from_mapping({"calibration": {"flat_field": bad}})
