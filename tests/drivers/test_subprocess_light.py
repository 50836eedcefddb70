"""Lights behind the ``subprocess`` transport: the profile's transport replaces the driver's
default serial port, bytes go to a child program's stdin and come back from its stdout."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from core.errors import RigError
from drivers.registry import open_light
from drivers.transports.replay import ScriptedTransport

EMULATOR = [sys.executable, "-m", "drivers.lights.rgbcw_emulator"]
ROOT = Path(__file__).parents[2]


def spec(command: list[str], **transport: object) -> dict[str, object]:
    return {
        "driver": "rgbcw-serial",
        "transport": {"type": "subprocess", "command": command, **transport},
        "boot_tries": 1,
    }


def test_rgbcw_light_through_a_child_process_emulating_the_firmware(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(ROOT)  # the child imports drivers from the checkout
    record = tmp_path / "session.jsonl"
    light = open_light(spec(EMULATOR, record=str(record)))
    try:
        light.set_levels({"r": 0.5, "w": 1.0})
        assert light.read_levels() == {"r": 0.5001, "g": 0.0, "b": 0.0, "c": 0.0, "w": 1.0}
        light.off()
        assert light.describe()["transport"]["type"] == "subprocess"
    finally:
        light.close()
    requests = [json.loads(line)["request"] for line in record.read_text().splitlines()]
    assert [bytes.fromhex(r) for r in requests] == [
        b"ID?\n",
        b"SET r=0.5000 g=0.0000 b=0.0000 c=0.0000 w=1.0000\n",
        b"GET?\n",
        b"OFF\n",
    ]


def test_the_recorded_bytes_replay_as_a_script(tmp_path: Path, monkeypatch) -> None:
    """The exchange with the child, byte for byte, is a script the driver must follow again."""
    monkeypatch.chdir(ROOT)
    record = tmp_path / "session.jsonl"
    light = open_light(spec(EMULATOR, record=str(record)))
    light.set_levels({"g": 0.25})
    light.close()
    from drivers.lights.rgbcw_serial import RgbcwSerialLight

    with ScriptedTransport.from_jsonl(record) as script:
        RgbcwSerialLight(script).set_levels({"g": 0.25})
    with pytest.raises(AssertionError, match="byte 17 differs"):  # not the recorded bytes
        with ScriptedTransport.from_jsonl(record) as script:
            RgbcwSerialLight(script).set_levels({"g": 0.5})


def test_a_child_that_exits_is_named_with_its_status(monkeypatch) -> None:
    child = [sys.executable, "-c", "import sys; sys.stderr.write('no lamp'); sys.exit(3)"]
    with pytest.raises(RigError, match=r"exited with status 3: no lamp"):
        open_light(spec(child))


def test_a_missing_program_is_named() -> None:
    with pytest.raises(RigError, match=r"program '/nonexistent/bridge' not found"):
        open_light(spec(["/nonexistent/bridge"]))


def test_the_serial_defaults_still_apply_to_a_serial_transport() -> None:
    with pytest.raises(RigError, match="/dev/nonexistent-tty"):
        open_light({"driver": "rgbcw-serial", "transport": {"port": "/dev/nonexistent-tty"}})
