"""The reference firmware sketch (docs/firmware/) compiled for the host with a tiny Arduino
shim answers exactly like the Python emulator the driver tests use."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from drivers.lights.rgbcw_emulator import RgbcwEmulator

REPO = Path(__file__).resolve().parents[2]
SKETCH = REPO / "docs" / "firmware" / "rgbcw_controller.ino"
LINES = [
    "ID?",
    "SET r=0.5 c=1",
    "GET?",
    "SET g=0.25 w=0.75",
    "GET?",
    "SET r=0.5 q=1",
    "SET r=1.5",
    "SET b=abc",
    "SET r",
    "BLINK",
    "SET " + "r=0.1 " * 30,
    "",
    "GET?",
    "OFF",
    "GET?",
]


@pytest.fixture(scope="module")
def firmware(tmp_path_factory: pytest.TempPathFactory) -> Path:
    compiler = shutil.which("g++")
    if compiler is None:
        pytest.skip("g++ not installed")
    out = tmp_path_factory.mktemp("fw")
    source = out / "sketch.cpp"
    source.write_text('#include "Arduino.h"\n' + SKETCH.read_text())
    binary = out / "rgbcw"
    build = subprocess.run(
        [compiler, "-std=c++17", "-Wall", "-Werror", "-DSERIAL_ID=\"EMU0001\"", "-I",
         str(Path(__file__).parent / "arduino_shim"), str(source), "-o", str(binary)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert build.returncode == 0, f"the sketch does not compile:\n{build.stderr}"
    return binary


def test_firmware_and_emulator_agree_line_for_line(firmware: Path) -> None:
    result = subprocess.run(
        [str(firmware)], input="\r\n".join(LINES) + "\n", capture_output=True, text=True, timeout=30
    )
    emulator = RgbcwEmulator()
    expected = ["READY"] + [reply for line in LINES if (reply := emulator.respond(line))]
    assert result.stdout.splitlines() == expected
