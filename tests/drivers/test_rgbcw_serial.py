"""The plain-text RGBCW controller: byte scripts, and the real serial driver talking through
a pseudo-terminal to the Python twin of the reference firmware."""

from __future__ import annotations

import pytest

from core.errors import RigError
from drivers.lights.rgbcw_emulator import PWM_MAX, RgbcwEmulator, serve_pty
from drivers.lights.rgbcw_serial import RgbcwSerialLight
from drivers.transports import open_transport
from drivers.transports.replay import ScriptedTransport

ID_LINE = b"ID model=rig-rgbcw fw=1.0.0 serial=A17 channels=r,g,b,c,w pwm_bits=12\n"
ILLUMINATIONS = {"LED1": {"c": 1.0}, "MIX": {"r": 0.25, "w": 0.5}}


def test_set_illumination_and_off_bytes() -> None:
    script = [
        (b"ID?\n", ID_LINE),
        (b"SET r=0.2500 g=0.0000 b=0.0000 c=0.0000 w=0.5000\n", b"OK\n"),
        (b"OFF\n", b"OK\n"),
    ]
    with ScriptedTransport(script) as t:
        light = RgbcwSerialLight(t, illuminations=ILLUMINATIONS)
        light.set_illumination("MIX")
        light.off()
    assert light.describe()["device"]["serial"] == "A17"


def test_boot_banner_and_a_first_silent_try_are_tolerated() -> None:
    script = [(b"ID?\n", b""), (b"ID?\n", b"READY\n" + ID_LINE)]
    with ScriptedTransport(script) as t:
        RgbcwSerialLight(t)


def test_id_lost_in_the_reset_is_asked_again_after_the_banner() -> None:
    # The board resets when the port opens: the first ID? is lost, READY comes, then silence.
    script = [(b"ID?\n", b"READY\n"), (b"ID?\n", ID_LINE)]
    with ScriptedTransport(script) as t:
        RgbcwSerialLight(t)


def test_err_reply_becomes_a_rig_error_with_the_reason() -> None:
    script = [
        (b"ID?\n", ID_LINE),
        (b"SET r=0.0000 g=0.0000 b=0.0000 c=1.0000 w=0.0000\n", b"ERR overheated\n"),
    ]
    with ScriptedTransport(script) as t:
        light = RgbcwSerialLight(t, illuminations=ILLUMINATIONS)
        with pytest.raises(RigError, match="overheated"):
            light.set_illumination("LED1")


def test_wrong_device_and_missing_channels() -> None:
    with ScriptedTransport([(b"ID?\n", b"Hello from a GPS\n")]) as t:
        with pytest.raises(RigError, match="does not speak rgbcw-text/1"):
            RgbcwSerialLight(t)
    rgb_only = b"ID model=x fw=1 serial=1 channels=r,g,b\n"
    with ScriptedTransport([(b"ID?\n", rgb_only)]) as t:
        with pytest.raises(RigError, match="profile uses c, w"):
            RgbcwSerialLight(t)


def test_device_not_answering() -> None:
    with ScriptedTransport([(b"ID?\n", b"")] * 3) as t:
        with pytest.raises(RigError, match="did not answer"):
            RgbcwSerialLight(t, boot_tries=3)


def test_emulator_follows_the_protocol() -> None:
    emu = RgbcwEmulator()
    assert emu.respond("SET r=0.5 q=1") == "ERR unknown channel q"
    assert emu.respond("SET r=1.5") == "ERR out of range r=1.5"
    assert emu.respond("SET r=abc") == "ERR bad value abc"
    assert emu.respond("BLINK") == "ERR unknown command BLINK"
    assert emu.respond("SET " + "r=0.1 " * 30) == "ERR line too long"
    assert emu.respond("SET g=1") == "OK" and emu.duty["g"] == PWM_MAX and emu.duty["r"] == 0


def test_serial_driver_through_a_pty_to_the_firmware_emulator() -> None:
    with serve_pty() as (port, emulator):
        transport = open_transport(
            {"type": "serial", "port": port, "baudrate": 115200, "timeout_s": 2}
        )
        light = RgbcwSerialLight(transport, illuminations=ILLUMINATIONS)
        try:
            assert light.identity["model"] == "rig-rgbcw"
            light.set_illumination("MIX")
            assert emulator.duty == {
                "r": round(0.25 * PWM_MAX),
                "g": 0,
                "b": 0,
                "c": 0,
                "w": round(0.5 * PWM_MAX),
            }
            assert light.read_levels() == pytest.approx(
                {"r": 0.25, "g": 0, "b": 0, "c": 0, "w": 0.5}, abs=1e-3
            )
            light.off()
            assert not any(emulator.duty.values())
        finally:
            light.close()
    assert emulator.lines[0] == "ID?"


def test_a_recorded_real_session_replays_as_a_byte_script(tmp_path) -> None:
    """Record the pty session with `record:`, then run the same steps against the replay."""
    recording = tmp_path / "rgbcw.jsonl"

    def steps(light: RgbcwSerialLight) -> None:
        light.set_illumination("LED1")
        light.off()

    with serve_pty() as (port, _):
        spec = {"type": "serial", "port": port, "timeout_s": 2, "record": str(recording)}
        light = RgbcwSerialLight(open_transport(spec), illuminations=ILLUMINATIONS)
        steps(light)
        light.close()
    with ScriptedTransport.from_jsonl(recording) as replay:
        steps(RgbcwSerialLight(replay, illuminations=ILLUMINATIONS))
    assert b"SET r=0.0000 g=0.0000 b=0.0000 c=1.0000 w=0.0000\n" in [r for r, _ in replay.exchanges]
