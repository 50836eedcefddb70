"""Profiles: the shipped ones load; malformed ones name the file, the key and what is allowed."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml

from core.errors import RigError
from drivers.sim.world import world_config
from rig.capture.devices import device_set
from rig.capture.engine import coverage_hint
from rig.cli import main
from rig.profile import load_profile, shipped_profiles

SHIPPED = (
    "sim",
    "sim-projector",
    "bulb-gphoto2",
    "bulb-manual-handheld",
    "dmx-gphoto2",
    "projector-gphoto2",
)


def sim_data() -> dict[str, Any]:
    return yaml.safe_load(Path(str(load_profile("sim").source)).read_text())


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_profiles_load_by_name(name: str) -> None:
    assert name in shipped_profiles()
    profile = load_profile(name)
    assert profile.name == name
    assert profile.plan.views >= 1 and profile.plan.illuminations
    assert "camera" in profile.devices


def test_profile_loads_by_path(tmp_path: Path) -> None:
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump({**sim_data(), "name": "mine"}))
    assert load_profile(path).name == "mine"
    assert load_profile(str(path)).source == str(path)


def _set(data: dict[str, Any], dotted: str, value: Any) -> None:
    *parents, last = dotted.split(".")
    for key in parents:
        data = data[key]
    if value is DELETE:
        del data[last]
    else:
        data[last] = value


DELETE = object()
MALFORMED = [
    # (dotted key, new value, text the error must contain)
    ("plan.views", "ten", "'plan.views'"),
    ("plan.views", 0, "'plan.views'"),
    ("plan.illuminations", ["LED1", "LED9"], "LED9"),
    ("plan.illuminations", ["LED1", "LED1"], "repeats"),
    ("plan.ambient", "yes", "'plan.ambient'"),
    ("plan.settle_s", -1, "'plan.settle_s'"),
    ("plan.shots", 3, "'plan.shots'"),
    ("plan.structured_light", {"gray_code": True}, "needs a projector"),
    ("devices.camera", DELETE, "'devices.camera'"),
    ("devices.light.driver", DELETE, "'devices.light.driver'"),
    ("devices.lamp", {"driver": "sim"}, "'devices.lamp'"),
    ("devices.light.driver", "hue-bridge", "tuya"),  # unknown driver: lists the known ones
    ("devices.light.transport", "/dev/ttyUSB0", "'devices.light.transport'"),
    ("illuminations.LED1", {"c": 1.5}, "'illuminations.LED1.c'"),
    ("illuminations.LED1", {"c": "full"}, "'illuminations.LED1.c'"),
    ("illuminations.ambient", {"w": 1.0}, "structured-light"),
    ("illuminations.white", {"w": 1.0}, "'illuminations.white'"),
    ("illuminations", {}, "'illuminations'"),
    ("light_mount.type", "tripod", "plate, free"),
    ("light_mount.offset_m", [0.1, 0.0], "'light_mount.offset_m'"),
    ("light_mount.diameter_m", -0.06, "'light_mount.diameter_m'"),
    ("camera_settings.exposure_s", 0, "'camera_settings.exposure_s'"),
    ("calibration.camera", DELETE, "'calibration.camera'"),
    ("known_distances.light_offset_m", -0.1, "'known_distances.light_offset_m'"),
    ("known_distances.tape", 1.0, "'known_distances.tape'"),
    ("poses", "guess", "estimate, known"),
    ("known_distances.camera_pairs", [{"views": [0, 99], "metres": 1.0}], "camera_pairs[0]"),
    ("known_distances.camera_pairs", [{"views": [0, 1], "metres": 0}], "metres"),
    ("plan", DELETE, "'plan'"),
    ("board", "A3", "'board'"),
    ("board.squares", [1, 7], "board squares 1x7"),
    ("board.marker_length_m", 0.05, "board marker length"),
    ("board.square_length_m", DELETE, "board.square_length_m"),
    ("plan.projector", {"placements": 2}, "'plan.projector' needs a projector"),
    ("plan.trajectory.distance_factors", [0.7, -1.0], "'plan.trajectory.distance_factors'"),
    ("plan.trajectory.distance_factors", "closer", "'plan.trajectory.distance_factors'"),
]


@pytest.mark.parametrize(
    ("key", "value", "expected"), MALFORMED, ids=[f"{k}={v!r}"[:40] for k, v, _ in MALFORMED]
)
def test_malformed_profile_names_file_key_and_allowed(
    tmp_path: Path, key: str, value: Any, expected: str, capsys: pytest.CaptureFixture[str]
) -> None:
    data = copy.deepcopy(sim_data())
    _set(data, key, value)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(RigError) as error:
        load_profile(path)
    message = str(error.value)
    assert str(path) in message and expected in message
    assert error.value.fix  # says what is allowed
    code = main(["capture", "--profile", str(path), "--out", str(tmp_path / "s"), "--yes"])
    assert code == 2
    err = capsys.readouterr().err
    assert "bad.yaml" in err.replace("\n", "")
    assert not (tmp_path / "s").exists()  # nothing was created for a bad profile


def test_yaml_syntax_error_and_unknown_name(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("devices: [\n")
    with pytest.raises(RigError, match="broken.yaml is not valid YAML"):
        load_profile(path)
    with pytest.raises(RigError, match="no shipped profile named 'simm'"):
        load_profile("simm")
    with pytest.raises(RigError, match="does not exist"):
        load_profile(tmp_path / "missing.yaml")
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    with pytest.raises(RigError, match="empty"):
        load_profile(empty)


def test_distance_factors_step_the_sim_and_prompt_the_person(tmp_path: Path) -> None:
    data = copy.deepcopy(sim_data())
    data["plan"]["trajectory"] = {"elevations_deg": [30], "distance_factors": [0.8, 1.0, 1.3]}
    data["sim"] = {"trajectory": {"radius_m": 0.5}}
    path = tmp_path / "stepped.yaml"
    path.write_text(yaml.safe_dump(data))
    trajectory = load_profile(path).plan.trajectory
    assert [trajectory.distance_factor(v) for v in range(4)] == [0.8, 1.0, 1.3, 0.8]
    config = world_config(device_set(load_profile(path), 0))
    assert config["trajectory"]["distances_m"] == pytest.approx([0.4, 0.5, 0.65])
    directions = [(0.0, 30.0), (120.0, 30.0), (240.0, 30.0)]
    assert "distance 0.8× the usual (step closer)" in coverage_hint(
        directions, [], 0, trajectory.distance_factor(0)
    )
    assert "usual distance" in coverage_hint(directions, [0], 1, trajectory.distance_factor(1))
    assert "1.3× the usual (step back)" in coverage_hint(
        directions, [0], 2, trajectory.distance_factor(2)
    )
    assert "distance" not in coverage_hint(directions, [0], 1, None)
