"""DMX interfaces, byte by byte: Enttec DMX USB Pro (serial), uDMX (USB control transfers),
Velleman K8062 (8-byte HID reports)."""

from __future__ import annotations

from typing import Any

import pytest

from core.errors import RigError
from drivers.lights.enttec import EnttecDmxPro
from drivers.lights.k8062 import VellemanK8062, frame_reports
from drivers.lights.udmx import UDmx
from drivers.transports.replay import ScriptedTransport

CHANNELS = {"r": 1, "g": 2, "b": 3, "c": 4, "w": 5}
ILLUMINATIONS = {"LED1": {"c": 1.0}, "RED": {"r": 0.5}}

SERIAL_REQUEST = bytes([0x7E, 10, 0, 0, 0xE7])
SERIAL_REPLY = bytes([0x7E, 10, 4, 0, 0x78, 0x56, 0x34, 0x12, 0xE7])
PARAMS_REQUEST = bytes([0x7E, 3, 2, 0, 0, 0, 0xE7])
PARAMS_REPLY = bytes([0x7E, 3, 5, 0, 0x2C, 0x01, 9, 1, 40, 0xE7])
HELLO = [(SERIAL_REQUEST, SERIAL_REPLY), (PARAMS_REQUEST, PARAMS_REPLY)]


def enttec_dmx(slots: dict[int, int]) -> bytes:
    """Label 6 with start code 0 and 512 slots, written out independently of the driver."""
    universe = bytearray(512)
    for address, value in slots.items():
        universe[address - 1] = value
    return bytes([0x7E, 6, 0x01, 0x02, 0x00]) + bytes(universe) + bytes([0xE7])


def test_enttec_reads_identity_then_sends_label_6_universes() -> None:
    script = [
        *HELLO,
        (enttec_dmx({4: 255, 7: 255}), b""),
        (enttec_dmx({1: 128, 7: 255}), b""),
        (enttec_dmx({7: 255}), b""),
    ]
    slept: list[float] = []
    with ScriptedTransport(script) as t:
        light = EnttecDmxPro(
            t, CHANNELS, ILLUMINATIONS, settle_s=0.5, fixed={7: 255}, sleep=slept.append
        )
        assert light.identity == {
            "serial": "12345678",
            "firmware": "1.44",
            "break_us": 96.0,
            "mark_after_break_us": 10.7,
            "refresh_hz": 40,
        }
        light.set_illumination("LED1")
        light.set_illumination("RED")
        light.off()
    assert slept == [0.5, 0.5]
    assert light.describe()["serial"] == "12345678"


def test_enttec_skips_stray_bytes_before_a_reply() -> None:
    script = [(SERIAL_REQUEST, b"\x00\x11" + SERIAL_REPLY), (PARAMS_REQUEST, PARAMS_REPLY)]
    with ScriptedTransport(script) as t:
        assert EnttecDmxPro(t, CHANNELS).identity["serial"] == "12345678"


def test_enttec_silent_widget_suggests_identify_false() -> None:
    with ScriptedTransport([(SERIAL_REQUEST, b"")]) as t:
        with pytest.raises(RigError, match="identify: false"):
            EnttecDmxPro(t, CHANNELS)


def test_enttec_without_identify_sends_only_dmx() -> None:
    with ScriptedTransport([(enttec_dmx({2: 64}), b"")]) as t:
        EnttecDmxPro(t, CHANNELS, identify=False).set_levels({"g": 64 / 255})


def test_levels_are_validated_before_anything_is_sent() -> None:
    with ScriptedTransport([]) as t:
        light = EnttecDmxPro(t, CHANNELS, ILLUMINATIONS, identify=False)
        with pytest.raises(RigError, match="outside 0..1"):
            light.set_levels({"r": 1.5})
        with pytest.raises(RigError, match="unknown channel"):
            light.set_levels({"uv": 0.2})
        with pytest.raises(RigError, match="known: LED1, RED"):
            light.set_illumination("LED9")


def test_bad_channel_maps_are_rejected() -> None:
    with pytest.raises(RigError, match="outside the DMX universe"):
        EnttecDmxPro(ScriptedTransport([]), {"r": 513}, identify=False)
    with pytest.raises(RigError, match="both a channel and fixed"):
        EnttecDmxPro(ScriptedTransport([]), {"r": 1}, fixed={1: 255}, identify=False)
    for bad in (256, "full", 127.5):  # as a profile might write them
        fixed: dict[int, Any] = {6: bad}
        with pytest.raises(RigError, match="fixed.6 = .* is not a DMX value"):
            EnttecDmxPro(ScriptedTransport([]), {"r": 1}, fixed=fixed, identify=False)
    with pytest.raises(RigError, match="illuminations.X names unknown channel"):
        EnttecDmxPro(ScriptedTransport([]), {"r": 1}, {"X": {"c": 1}}, identify=False)


def test_udmx_sends_one_set_channel_range_control_transfer() -> None:
    # bmRequestType 0x40 (vendor, device, OUT), bRequest 2, wValue = count 5,
    # wIndex = first slot 0, wLength 5, then the levels.
    setup = bytes([0x40, 0x02, 0x05, 0x00, 0x00, 0x00, 0x05, 0x00])
    script = [
        (setup + bytes([0, 0, 0, 255, 0]), None),
        (setup + bytes([0, 0, 0, 0, 0]), None),
    ]
    with ScriptedTransport(script) as t:
        light = UDmx(t, CHANNELS, ILLUMINATIONS)
        light.set_illumination("LED1")
        light.off()


def test_k8062_sends_each_frame_twice_so_the_widget_outputs_it() -> None:
    # The widget outputs a frame only when the next one starts: the second copy releases it.
    cool = bytes([4, 1, 0, 0, 0, 255, 0, 0])
    dark = bytes([4, 1, 0, 0, 0, 0, 0, 0])
    with ScriptedTransport([(cool, None), (cool, None), (dark, None), (dark, None)]) as t:
        light = VellemanK8062(t, CHANNELS, ILLUMINATIONS)
        light.set_illumination("LED1")
        light.off()


def test_k8062_compresses_leading_zeros_and_sends_trailing_slots_singly() -> None:
    # Fixture at DMX 20..24 (24 slots): the start report may skip zeros only while 6 slots
    # remain after them, so it skips 18 (sent as 19: the start code counts) and carries
    # slots 19..24.
    channels = {"r": 20, "g": 21, "b": 22, "c": 23, "w": 24}
    start = bytes([4, 19, 0, 10, 20, 30, 40, 50])
    with ScriptedTransport([(start, None), (start, None)]) as t:
        VellemanK8062(t, channels).set_levels(
            {k: v / 255 for k, v in zip("rgbcw", (10, 20, 30, 40, 50), strict=True)}
        )
    slots = bytes(range(1, 16))  # 15 non-zero slots: start(6) + intermediate(7) + 2 singles
    assert frame_reports(slots) == [
        bytes([4, 1, 1, 2, 3, 4, 5, 6]),
        bytes([2, 7, 8, 9, 10, 11, 12, 13]),
        bytes([3, 14, 0, 0, 0, 0, 0, 0]),
        bytes([3, 15, 0, 0, 0, 0, 0, 0]),
    ]
    gap = bytes([9] * 6) + bytes(20) + bytes([7] * 8)  # zeros in the middle: report type 5
    assert frame_reports(gap)[1] == bytes([5, 20, 7, 7, 7, 7, 7, 7])
