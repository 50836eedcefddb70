"""Wi-Fi bulbs: Magic Home bytes over TCP (scripted and against a local fake bulb), Tuya
through a fake tinytuya device object."""

from __future__ import annotations

import re
import socket
import sys
import threading

import pytest

from core.errors import MissingDependencyError, RigError
from core.install import install_command
from drivers.lights.magichome import MagicHomeLight
from drivers.lights.tuya import TuyaBulb
from drivers.transports.replay import ScriptedTransport
from drivers.transports.tcp import TcpTransport

STATE_QUERY = bytes([0x81, 0x8A, 0x8B, 0x96])
# A 5-channel controller, powered off: head 81, model 25, power 24, ..., checksum.
STATE_BODY = bytes([0x81, 0x25, 0x24, 0x61, 0x21, 0x06, 0, 0, 0, 0, 0x09, 0, 0x0F])
STATE_REPLY = STATE_BODY + bytes([sum(STATE_BODY) & 0xFF])
POWER_ON = bytes([0x71, 0x23, 0x0F, 0xA3])
POWER_OFF = bytes([0x71, 0x24, 0x0F, 0xA4])


def levels_msg(r: int, g: int, b: int, ww: int, cw: int, mode: int) -> bytes:
    body = bytes([0x31, r, g, b, ww, cw, mode, 0x0F])
    return body + bytes([sum(body) & 0xFF])


def test_magic_home_levels_use_the_0x31_message_with_checksum() -> None:
    # {c: 1} -> cool white byte 5 = 255; written out by hand: 31 00 00 00 00 ff 00 0f 3f
    assert levels_msg(0, 0, 0, 0, 255, 0) == bytes.fromhex("31 00 00 00 00 ff 00 0f 3f")
    script = [
        (STATE_QUERY, STATE_REPLY),
        (POWER_ON, None),
        (levels_msg(0, 0, 0, 0, 255, 0x00), None),
        (levels_msg(128, 0, 0, 0, 0, 0x00), None),
        (POWER_OFF, None),
    ]
    with ScriptedTransport(script) as t:
        light = MagicHomeLight(t, {"LED1": {"c": 1.0}, "RED": {"r": 0.5}})
        assert light.describe()["firmware"] == 9
        light.set_illumination("LED1")
        light.set_illumination("RED")
        light.off()


def test_magic_home_exclusive_white_modes() -> None:
    script = [
        (STATE_QUERY, STATE_REPLY),
        (POWER_ON, None),
        (levels_msg(0, 0, 0, 255, 0, 0x0F), None),
        (levels_msg(0, 0, 255, 0, 0, 0xF0), None),
    ]
    with ScriptedTransport(script) as t:
        light = MagicHomeLight(t, exclusive_white=True)
        light.set_levels({"w": 1.0})
        light.set_levels({"b": 1.0})
        with pytest.raises(RigError, match="mixes colour and white"):
            light.set_levels({"b": 1.0, "w": 0.2})
    with pytest.raises(RigError, match="illumination 'BAD' mixes"):
        MagicHomeLight(ScriptedTransport([]), {"BAD": {"r": 1, "c": 1}}, exclusive_white=True)


def test_magic_home_rejects_a_corrupt_state_reply() -> None:
    corrupt = STATE_REPLY[:-1] + bytes([(STATE_REPLY[-1] + 1) & 0xFF])
    with ScriptedTransport([(STATE_QUERY, corrupt)]) as t:
        with pytest.raises(RigError, match="malformed Magic Home state"):
            MagicHomeLight(t)


def state_reply(model: int, firmware: int) -> bytes:
    body = bytes([0x81, model, 0x23, 0x61, 0x21, 0x06, 0, 0, 0, 0, firmware, 0, 0x0F])
    return body + bytes([sum(body) & 0xFF])


def test_magic_home_picks_the_protocol_from_flux_leds_model_database() -> None:
    # an RGBCW bulb (0x35) with firmware 7 speaks the 9-byte protocol that turns on by itself;
    # already on, so no power message; persist: false writes 0x41 instead of 0x31
    body = bytes([0x41, 0, 0, 0, 0, 255, 0x0F, 0x0F])  # whites only: mode 0F
    script = [(STATE_QUERY, state_reply(0x35, 7)), (body + bytes([sum(body) & 0xFF]), None)]
    with ScriptedTransport(script) as t:
        light = MagicHomeLight(t, persist=False, exclusive_white=True)
        assert light.protocol.name == "LEDENET_AUTO_ON"
        light.set_levels({"c": 1.0})
    # an RGB-only controller (8-byte levels, no white channels) is refused
    with ScriptedTransport([(STATE_QUERY, state_reply(0x33, 9))]) as t:
        with pytest.raises(RigError, match="model 0x33 .* speaks flux_led's .*8BYTE"):
            MagicHomeLight(t)


def wrapped_levels(
    counter: int, mode: int, hsv: tuple[int, int, int], white: tuple[int, int]
) -> bytes:
    """The 25-byte levels message written out from its documented layout: the outer wrapper
    b0 b1 b2 b3 00 01, version 02, a counter, the inner length 00 0e, then e0 01 00, the write
    mode, hue/2, saturation and value in %, white temperature (0 warm .. 100 cool) and
    brightness in %, 00 00 14 00 00, and the checksum of everything before it."""
    inner = bytes([0xE0, 0x01, 0x00, mode, *hsv, *white, 0x00, 0x00, 0x14, 0x00, 0x00])
    body = bytes([0xB0, 0xB1, 0xB2, 0xB3, 0x00, 0x01, 0x02, counter, 0x00, len(inner)]) + inner
    return body + bytes([sum(body) & 0xFF])


def test_magic_home_rgbcw_bulb_from_firmware_10_takes_the_25_byte_message() -> None:
    script = [
        (STATE_QUERY, state_reply(0x35, 10)),  # already on: no power message
        (wrapped_levels(0, 0xB1, (0, 0, 0), (100, 100)), None),  # {c: 1}: whites only
        (wrapped_levels(1, 0xA1, (120, 100, 100), (0, 0)), None),  # {b: 1}: hue 240 / 2
        (wrapped_levels(2, 0xB1, (0, 0, 0), (25, 40)), None),  # {c: .1, w: .3}: 26 + 77 of 255
    ]
    assert len(script[1][0]) == 25
    with ScriptedTransport(script) as t:
        light = MagicHomeLight(t, exclusive_white=True)
        assert light.protocol.name == "LEDENET_25_BYTE"
        light.set_levels({"c": 1.0})
        light.set_levels({"b": 1.0})
        light.set_levels({"c": 0.1, "w": 0.3})


def test_magic_home_without_flux_led_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "flux_led", None)
    with pytest.raises(MissingDependencyError, match=re.escape(install_command("flux"))):
        MagicHomeLight(ScriptedTransport([]))


def test_magic_home_over_a_real_tcp_socket() -> None:
    """A fake bulb on localhost answers the state query and records what it gets."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    received = bytearray()

    def bulb() -> None:
        conn, _ = server.accept()
        with conn:
            if conn.recv(4) == STATE_QUERY:
                conn.sendall(STATE_REPLY)
            while data := conn.recv(64):
                received.extend(data)

    thread = threading.Thread(target=bulb, daemon=True)
    thread.start()
    light = MagicHomeLight(TcpTransport("127.0.0.1", server.getsockname()[1], timeout_s=2))
    light.set_levels({"g": 1.0})
    light.close()
    thread.join(timeout=5)
    server.close()
    assert bytes(received) == POWER_ON + levels_msg(0, 255, 0, 0, 0, 0x00)


class FakeTuyaBulb:
    """Stands in for tinytuya.BulbDevice (its wire protocol is encrypted)."""

    def __init__(self, fail: bool = False) -> None:
        self.calls: list[tuple] = []
        self.id, self.address, self.key = "bf123", "192.168.1.40", ""
        self.fail = fail

    def set_version(self, version: float) -> None: ...

    def set_socketTimeout(self, seconds: float) -> None: ...

    def _record(self, *call: object) -> dict:
        self.calls.append(call)
        return {"Error": "Device Unreachable", "Err": "905"} if self.fail else {"dps": {}}

    def turn_on(self) -> dict:
        return self._record("turn_on")

    def turn_off(self) -> dict:
        return self._record("turn_off")

    def set_colour(self, r: int, g: int, b: int) -> dict:
        return self._record("set_colour", r, g, b)

    def set_white_percentage(self, brightness: int, colourtemp: int) -> dict:
        return self._record("set_white_percentage", brightness, colourtemp)


def test_tuya_maps_illuminations_to_colour_or_white_mode() -> None:
    bulb = FakeTuyaBulb()
    light = TuyaBulb(
        bulb,
        {"LED1": {"c": 1.0}, "WARM": {"w": 0.4}, "MIX": {"c": 0.3, "w": 0.3}, "RED": {"r": 0.5}},
        settle_s=0,
    )
    for name in ("LED1", "WARM", "MIX", "RED"):
        light.set_illumination(name)
    light.off()
    assert bulb.calls == [
        ("turn_on",),
        ("set_white_percentage", 100, 100),
        ("turn_on",),
        ("set_white_percentage", 40, 0),
        ("turn_on",),
        ("set_white_percentage", 60, 50),
        ("turn_on",),
        ("set_colour", 128, 0, 0),
        ("turn_off",),
    ]


def test_tuya_rejects_mixed_modes_and_reports_device_errors() -> None:
    with pytest.raises(RigError, match="colour or white, not both"):
        TuyaBulb(FakeTuyaBulb(), {"BAD": {"r": 1.0, "c": 0.5}})
    with pytest.raises(RigError, match="keep c \\+ w <= 1"):
        TuyaBulb(FakeTuyaBulb(), {"BRIGHT": {"c": 0.8, "w": 0.8}})
    light = TuyaBulb(FakeTuyaBulb(fail=True), {"LED1": {"c": 1.0}}, settle_s=0)
    with pytest.raises(RigError, match="Device Unreachable"):
        light.set_illumination("LED1")


def test_tuya_local_key_never_reaches_logs_or_provenance(monkeypatch, caplog) -> None:
    import json
    import logging
    import sys
    from types import SimpleNamespace

    from drivers.registry import open_light

    made: list[FakeTuyaBulb] = []

    def bulb_device(device_id: str, address: str, local_key: str) -> FakeTuyaBulb:
        bulb = FakeTuyaBulb()
        bulb.id, bulb.address, bulb.key = device_id, address, local_key
        made.append(bulb)
        return bulb

    monkeypatch.setitem(sys.modules, "tinytuya", SimpleNamespace(BulbDevice=bulb_device))
    spec = {
        "driver": "tuya",
        "device_id": "bf0123",
        "address": "192.168.1.40",
        "local_key": "SUPERSECRETKEY12",
        "illuminations": {"LED1": {"c": 1.0}},
        "settle_s": 0,
    }
    with caplog.at_level(logging.DEBUG):
        light = open_light(spec)
        light.set_illumination("LED1")
    assert made[0].key == "SUPERSECRETKEY12"  # the key reached the device...
    assert "SUPERSECRETKEY12" not in caplog.text  # ...but no log line
    assert "SUPERSECRETKEY12" not in json.dumps(light.describe())
    assert light.describe()["device_id"] == "bf0123"
