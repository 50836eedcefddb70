"""Transports: the scripted/recording test transports, and each real transport's error paths
against fake libraries or local endpoints (socket server, subprocess)."""

from __future__ import annotations

import errno
import json
import logging
import socket
import sys
import threading
from types import SimpleNamespace

import pytest

from core.errors import MissingDependencyError, RigError
from drivers.transports import open_transport, redact
from drivers.transports.base import NotAnsweringError
from drivers.transports.hid_device import HidTransport
from drivers.transports.replay import RecordingTransport, ScriptedTransport, ScriptMismatch
from drivers.transports.serial_port import SerialTransport
from drivers.transports.subprocess_pipe import SubprocessTransport
from drivers.transports.tcp import TcpTransport
from drivers.transports.usb_device import UsbTransport, control_in, control_out, setup_packet


# -- scripted transport ---------------------------------------------------------------------
def test_scripted_transport_replays_and_checks_every_byte() -> None:
    with ScriptedTransport([(b"ID?\n", b"ID x\n"), (None, b"late\n")]) as t:
        t.write(b"ID")
        t.write(b"?\n")  # split writes are joined before matching
        assert t.read_until(b"\n") == b"ID x\n"
        assert t.read_until(b"\n") == b"late\n"


def test_scripted_transport_reports_the_first_differing_byte() -> None:
    t = ScriptedTransport([(b"\x7e\x06\x01", b"")])
    with pytest.raises(ScriptMismatch, match="byte 1 differs"):
        t.write(b"\x7e\x07\x01")


def test_scripted_transport_fails_on_unused_exchanges_and_unread_replies() -> None:
    with pytest.raises(ScriptMismatch, match="1 exchange"):
        with ScriptedTransport([(b"A", b""), (b"B", b"")]) as t:
            t.write(b"A")
    with pytest.raises(ScriptMismatch, match="never read"):
        with ScriptedTransport([(b"A", b"reply")]) as t:
            t.write(b"A")
    with pytest.raises(ScriptMismatch, match="used up"):
        ScriptedTransport([]).write(b"A")


def test_silent_device_is_a_clear_rig_error() -> None:
    with ScriptedTransport([(b"ID?\n", b"")]) as t:
        t.write(b"ID?\n")
        with pytest.raises(NotAnsweringError, match="did not answer") as info:
            t.read_until(b"\n", what="the ID? reply")
    assert isinstance(info.value, RigError)
    assert "the ID? reply" in str(info.value)


def test_recording_then_replaying_a_session(tmp_path) -> None:
    log = tmp_path / "session.jsonl"
    inner = ScriptedTransport([(None, b"READY\n"), (b"ID?\n", b"ID a\n"), (b"OFF\n", b"OK\n")])
    with RecordingTransport(inner, log) as rec:
        assert rec.read_until(b"\n") == b"READY\n"
        rec.write(b"ID?\n")
        assert rec.read_until(b"\n") == b"ID a\n"
        rec.write(b"OFF\n")
        assert rec.read(3) == b"OK\n"
    inner.assert_done()
    lines = [json.loads(x) for x in log.read_text().splitlines()]
    assert lines[0] == {"request": None, "reply": b"READY\n".hex()}
    assert lines[2] == {"request": b"OFF\n".hex(), "reply": b"OK\n".hex()}
    with open_transport({"type": "replay", "file": str(log)}) as replay:
        assert isinstance(replay, ScriptedTransport)
        assert replay.read_until(b"\n") == b"READY\n"
        replay.write(b"ID?\n")
        assert replay.read_until(b"\n") == b"ID a\n"
        replay.write(b"OFF\n")
        assert replay.read(3) == b"OK\n"


def test_malformed_recording_names_the_line(tmp_path) -> None:
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"request": "00", "reply": ""}\n{"request": "zz"}\n')
    with pytest.raises(RigError, match=r"bad.jsonl:2"):
        ScriptedTransport.from_jsonl(bad)
    with pytest.raises(RigError, match="does not exist"):
        open_transport({"type": "replay", "file": str(tmp_path / "none.jsonl")})
    recorded = tmp_path / "good.jsonl"
    recorded.write_text('{"request": "00", "reply": ""}\n')
    spec = {"type": "replay", "file": str(recorded), "record": str(tmp_path / "no" / "x.jsonl")}
    with pytest.raises(RigError, match="cannot write the transport recording"):
        open_transport(spec)


# -- logging and secrets -----------------------------------------------------------------------
def test_every_exchange_is_logged_at_debug_with_secrets_masked(caplog) -> None:
    t = ScriptedTransport([(b"key=s3cret!\n", b"OK\n")])
    t._secrets = (b"s3cret!",)
    with caplog.at_level(logging.DEBUG, logger="drivers.transport"):
        t.write(b"key=s3cret!\n")
        t.read(3)
    text = caplog.text
    assert "s3cret" not in text and b"s3cret!".hex(" ") not in text
    assert "<secret>" in text and "4f 4b 0a" in text


def test_redact_masks_local_keys_at_any_depth() -> None:
    spec = {"driver": "tuya", "local_key": "abc", "transport": {"password": "x", "host": "h"}}
    assert redact(spec) == {
        "driver": "tuya",
        "local_key": "***",
        "transport": {"password": "***", "host": "h"},
    }


# -- open_transport -------------------------------------------------------------------------
def test_unknown_transport_type_lists_the_known_ones() -> None:
    with pytest.raises(RigError, match="serial, hid, usb, tcp, subprocess, replay"):
        open_transport({"type": "carrier-pigeon"})


def test_missing_transport_keys_are_a_rig_error() -> None:
    with pytest.raises(RigError, match="missing keys"):
        open_transport({"type": "tcp", "host": "127.0.0.1"})


def test_bad_transport_values_are_a_rig_error() -> None:
    with pytest.raises(RigError, match=r"key 'port' is 'fivefive' .*\[1, 65535\]"):
        open_transport({"type": "tcp", "host": "127.0.0.1", "port": "fivefive"})
    with pytest.raises(RigError, match="key 'timeout_s' is 'soon'"):
        open_transport({"type": "tcp", "host": "127.0.0.1", "port": 1, "timeout_s": "soon"})


@pytest.mark.parametrize(
    ("spec", "says"),
    [
        ({"type": "tcp", "host": "h", "port": 70_000}, r"key 'port' is 70000 .*\[1, 65535\]"),
        ({"type": "tcp", "host": "h", "port": 1, "timeout_s": 1e308}, r"key 'timeout_s'.*3600"),
        ({"type": "serial", "port": "/dev/x", "baudrate": 10**12}, r"key 'baudrate'"),
        ({"type": "serial", "port": "/dev/x", "timeout_s": float("nan")}, r"key 'timeout_s'"),
        ({"type": "hid", "vid": 0x1_0000, "pid": 1}, r"transport\.vid = 65536 is not a USB id"),
        ({"type": "usb", "vid": 1, "pid": -1}, r"transport\.pid = -1 is not a USB id"),
    ],
)
def test_transport_numbers_are_bounded_before_opening(spec: dict[str, object], says: str) -> None:
    with pytest.raises(RigError, match=says):
        open_transport(spec)


# -- serial -----------------------------------------------------------------------------------
def test_serial_port_missing() -> None:
    with pytest.raises(RigError, match="does not exist") as info:
        SerialTransport("/dev/ttyDOES-NOT-EXIST")
    assert "rig devices" in str(info.value)


def test_serial_permission_denied_gives_the_udev_hint() -> None:
    import serial

    class Denied:
        SerialException = serial.SerialException

        @staticmethod
        def Serial(**kwargs: object) -> None:
            raise serial.SerialException(errno.EACCES, "could not open port: Permission denied")

    with pytest.raises(RigError, match="permission denied") as info:
        SerialTransport("/dev/ttyUSB0", serial_module=Denied)
    assert "dialout" in str(info.value) and "udev" in str(info.value)


def test_serial_write_timeout_and_failure_are_rig_errors() -> None:
    import serial

    class StuckPort:
        def __init__(self, **kwargs: object) -> None:
            self.failure: Exception = serial.SerialTimeoutException("Write timeout")

        def write(self, data: bytes) -> None:
            raise self.failure

        def read(self, size: int) -> bytes:
            raise serial.SerialException("device reports readiness to read but returned no data")

    fake = SimpleNamespace(
        Serial=StuckPort,
        SerialException=serial.SerialException,
        SerialTimeoutException=serial.SerialTimeoutException,
    )
    t = SerialTransport("/dev/ttyUSB0", serial_module=fake, timeout_s=0.5)
    with pytest.raises(NotAnsweringError, match="ttyUSB0 did not answer within 0.5 s"):
        t.write(b"x")
    with pytest.raises(RigError, match="serial port /dev/ttyUSB0 failed"):
        t.read(1)


# -- TCP ----------------------------------------------------------------------------------------
@pytest.fixture
def tcp_server():
    """A local server replying b'pong' to b'ping', silent otherwise."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def serve() -> None:
        conn, _ = server.accept()
        with conn:
            while data := conn.recv(64):
                if data == b"ping":
                    conn.sendall(b"pong")

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield server.getsockname()[1]
    server.close()


def test_tcp_exchange_and_timeout(tcp_server: int) -> None:
    with TcpTransport("127.0.0.1", tcp_server, timeout_s=0.2) as t:
        t.write(b"ping")
        assert t.read_exactly(4) == b"pong"
        t.write(b"other")
        with pytest.raises(NotAnsweringError):
            t.read_exactly(4)


def test_tcp_connection_refused() -> None:
    probe = socket.socket()
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()  # nothing listens there now
    with pytest.raises(RigError, match=f"cannot connect to 127.0.0.1:{port}"):
        TcpTransport("127.0.0.1", port, timeout_s=0.5)


# -- subprocess -------------------------------------------------------------------------------
def test_subprocess_transport_talks_to_a_helper_program() -> None:
    code = "import sys\nfor line in sys.stdin:\n    print(line.strip().upper(), flush=True)"
    with SubprocessTransport([sys.executable, "-c", code], timeout_s=5) as t:
        t.write(b"hello\n")
        assert t.read_until(b"\n") == b"HELLO\n"


def test_subprocess_missing_program() -> None:
    with pytest.raises(RigError, match="not found"):
        SubprocessTransport("no-such-program-xyz --flag")


def test_subprocess_chatty_stderr_does_not_block_the_helper() -> None:
    # 200 kB of log lines would fill an undrained stderr pipe and freeze the helper
    code = (
        "import sys; sys.stderr.write('log line\\n' * 25000); sys.stderr.flush(); "
        "sys.stdin.readline(); sys.stdout.write('ok\\n'); sys.stdout.flush()"
    )
    with SubprocessTransport([sys.executable, "-c", code], timeout_s=10) as t:
        t.write(b"go\n")
        assert t.read_until(b"\n") == b"ok\n"


def test_subprocess_exit_is_reported_with_its_stderr() -> None:
    code = "import sys; sys.stderr.write('boom'); sys.exit(3)"
    t = SubprocessTransport([sys.executable, "-c", code], timeout_s=5)
    t._proc.wait()
    with pytest.raises(RigError, match="status 3: boom"):
        t.write(b"x")


# -- USB ------------------------------------------------------------------------------------------
class FakeUsbError(Exception):
    def __init__(self, message: str, code: int | None = None) -> None:
        super().__init__(message)
        self.errno = code


class FakeUsbDevice:
    def __init__(
        self, reply: bytes = b"", error: Exception | None = None, product: str | None = None
    ) -> None:
        self.calls: list[tuple] = []
        self.reply = reply
        self.error = error
        self._product = product

    @property
    def product(self) -> str:
        if self._product is None:  # what pyusb raises without permission to read strings
            raise ValueError("The device has no langid (permission issue, ...)")
        return self._product

    def ctrl_transfer(self, *args: object):
        self.calls.append(args)
        if self.error:
            raise self.error
        return self.reply


def fake_usb_core(devices: list, no_backend: bool = False) -> SimpleNamespace:
    class NoBackendError(Exception):
        pass

    def find(**kwargs: object):
        if no_backend:
            raise NoBackendError("No backend available")
        return iter(devices)

    return SimpleNamespace(
        find=find,
        NoBackendError=NoBackendError,
        USBError=FakeUsbError,
        USBTimeoutError=type("USBTimeoutError", (FakeUsbError,), {}),
    )


def test_usb_control_transfers_map_setup_bytes_to_pyusb_calls() -> None:
    dev = FakeUsbDevice(reply=b"\x01\x02")
    t = UsbTransport(0x16C0, 0x05DC, usb_core=fake_usb_core([dev]), timeout_s=0.5)
    control_out(t, 0x40, 2, 3, 0, b"\x10\x20\x30")
    assert dev.calls[-1] == (0x40, 2, 3, 0, b"\x10\x20\x30", 500)
    assert control_in(t, 0xC0, 7, 0, 1, 2) == b"\x01\x02"
    assert dev.calls[-1] == (0xC0, 7, 0, 1, 2, 500)
    assert setup_packet(0x40, 2, 3, 0, 3) == bytes([0x40, 2, 3, 0, 0, 0, 3, 0])


def test_usb_without_libusb_names_the_debian_package() -> None:
    with pytest.raises(MissingDependencyError, match="libusb-1.0-0"):
        UsbTransport(0x16C0, 0x05DC, usb_core=fake_usb_core([], no_backend=True))


def test_usb_device_absent_or_not_permitted() -> None:
    with pytest.raises(RigError, match="no USB device 16c0:05dc"):
        UsbTransport(0x16C0, 0x05DC, usb_core=fake_usb_core([]))
    dev = FakeUsbDevice(error=FakeUsbError("Access denied", errno.EACCES))
    t = UsbTransport(0x16C0, 0x05DC, usb_core=fake_usb_core([dev]))
    with pytest.raises(RigError, match="udev"):
        control_out(t, 0x40, 2, 1, 0, b"\x00")


def test_usb_product_string_picks_the_udmx_among_shared_ids() -> None:
    # 16c0:05dc is V-USB's shared id: a USBasp programmer answers to it as well.
    usbasp, udmx = FakeUsbDevice(product="USBasp"), FakeUsbDevice(product="uDMX")
    core = fake_usb_core([usbasp, udmx])
    control_out(UsbTransport(0x16C0, 0x05DC, product="uDMX", usb_core=core), 0x40, 2, 1, 0, b"\x07")
    assert udmx.calls and not usbasp.calls
    with pytest.raises(RigError, match="is 'USBasp', not 'uDMX'"):
        UsbTransport(0x16C0, 0x05DC, product="uDMX", usb_core=fake_usb_core([usbasp]))
    unreadable = FakeUsbDevice()  # pyusb cannot read its product string
    with pytest.raises(RigError, match="permission denied") as info:
        UsbTransport(0x16C0, 0x05DC, product="uDMX", usb_core=fake_usb_core([unreadable]))
    assert "udev" in str(info.value)


# -- HID ------------------------------------------------------------------------------------------
class FakeHidDevice:
    def __init__(self, fail_open: bool = False) -> None:
        self.fail_open = fail_open
        self.unplugged = False
        self.written: list[bytes] = []

    def open(self, vid: int, pid: int, serial: str | None) -> None:
        if self.fail_open:
            raise OSError("open failed")

    def write(self, data: bytes) -> int:
        if self.unplugged:
            return -1
        self.written.append(bytes(data))
        return len(data)

    def read(self, size: int, timeout_ms: int) -> list[int]:
        if self.unplugged:
            raise OSError("read error")
        return [1, 2, 3][:size]

    def close(self) -> None:
        pass


def fake_hid(device: FakeHidDevice, present: bool = True) -> SimpleNamespace:
    return SimpleNamespace(
        enumerate=lambda vid, pid: [{"vendor_id": vid}] if present else [],
        device=lambda: device,
    )


def test_hid_reports_get_report_id_zero_prepended() -> None:
    dev = FakeHidDevice()
    t = HidTransport(0x10CF, 0x8062, hid_module=fake_hid(dev))
    t.write(bytes([4, 1, 255, 0, 0, 0, 0, 0]))
    assert dev.written == [bytes([0, 4, 1, 255, 0, 0, 0, 0, 0])]
    assert t.read(8) == b"\x01\x02\x03"
    dev.unplugged = True
    with pytest.raises(RigError, match="writing to HID device 10cf:8062 failed"):
        t.write(bytes(8))
    with pytest.raises(RigError, match="reading from HID device 10cf:8062 failed: read error"):
        t.read(8)


def test_hid_absent_or_not_permitted() -> None:
    with pytest.raises(RigError, match="no HID device 10cf:8062"):
        HidTransport(0x10CF, 0x8062, hid_module=fake_hid(FakeHidDevice(), present=False))
    with pytest.raises(RigError, match="hidraw"):
        HidTransport(0x10CF, 0x8062, hid_module=fake_hid(FakeHidDevice(fail_open=True)))
