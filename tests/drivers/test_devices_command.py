"""`rig devices`: a table with the fitting driver, notes for missing libraries, exit 0."""

from __future__ import annotations

import sys
from types import SimpleNamespace

import pytest

from core.install import install_command
from rig.cli import main
from rig.commands import devices


def test_no_hardware_prints_none_found(monkeypatch, capsys) -> None:
    monkeypatch.setattr(devices, "PROBES", ())
    assert main(["devices"]) == 0
    assert "none found" in capsys.readouterr().out


def test_real_probes_never_crash(capsys) -> None:
    """On any machine (no hardware, no libusb, no gphoto2) the command still exits 0."""
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "none found" in out or "Connected devices" in out


def test_serial_ports_are_matched_to_drivers_by_vid_pid(monkeypatch) -> None:
    ports = [
        SimpleNamespace(
            device="/dev/ttyUSB0",
            vid=0x0403,
            pid=0x6001,
            description="FT232R",
            name="ttyUSB0",
            hwid="USB",
        ),
        SimpleNamespace(
            device="/dev/ttyACM0",
            vid=0x2341,
            pid=0x0043,
            description="Arduino Uno",
            name="ttyACM0",
            hwid="USB",
        ),
        SimpleNamespace(
            device="/dev/ttyS0", vid=None, pid=None, description="n/a", name="ttyS0", hwid="n/a"
        ),
    ]
    import serial.tools.list_ports

    monkeypatch.setattr(serial.tools.list_ports, "comports", lambda: ports)
    rows, notes = devices.discover((devices.probe_serial,))
    assert [(r.address, r.driver) for r in rows] == [
        ("/dev/ttyUSB0", "enttec-dmx-pro"),
        ("/dev/ttyACM0", "rgbcw-serial"),
    ]
    assert notes == []


def test_missing_libraries_become_notes(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "gphoto2", None)
    monkeypatch.setitem(sys.modules, "seabreeze.spectrometers", None)
    rows, notes = devices.discover((devices.probe_cameras, devices.probe_spectrometers))
    assert rows == []
    assert any(install_command("gphoto2") in n for n in notes)
    assert any(install_command("seabreeze") in n for n in notes)


def test_a_crashing_probe_is_a_note_not_a_crash() -> None:
    def broken() -> tuple[list[devices.Found], list[str]]:
        raise OSError("boom")

    rows, notes = devices.discover((broken,))
    assert rows == [] and notes == ["broken failed: OSError: boom"]


def test_hid_and_usb_probes_with_fake_libraries(monkeypatch) -> None:
    fake_hid = SimpleNamespace(
        enumerate=lambda: [
            {
                "vendor_id": 0x10CF,
                "product_id": 0x8062,
                "path": b"/dev/hidraw3",
                "product_string": "K8062",
            },
            {
                "vendor_id": 0x046D,
                "product_id": 0xC077,
                "path": b"/dev/hidraw0",
                "product_string": "Mouse",
            },
        ]
    )
    monkeypatch.setitem(sys.modules, "hid", fake_hid)
    rows, _ = devices.discover((devices.probe_hid,))
    assert [(r.address, r.driver) for r in rows] == [("/dev/hidraw3", "velleman-k8062")]

    class NoBackendError(Exception):
        pass

    def find(find_all: bool) -> list:
        return [
            SimpleNamespace(idVendor=0x16C0, idProduct=0x05DC, bus=1, address=4),
            SimpleNamespace(idVendor=0x2457, idProduct=0x101E, bus=1, address=5),
            # a USBasp programmer on V-USB's shared id is not offered as a uDMX
            SimpleNamespace(idVendor=0x16C0, idProduct=0x05DC, bus=1, address=6, product="USBasp"),
        ]

    monkeypatch.setitem(
        sys.modules, "usb.core", SimpleNamespace(find=find, NoBackendError=NoBackendError)
    )
    rows, _ = devices.discover((devices.probe_usb,))
    assert [r.driver for r in rows] == ["udmx", "seabreeze"]

    def no_backend(find_all: bool) -> list:
        raise NoBackendError

    monkeypatch.setitem(
        sys.modules, "usb.core", SimpleNamespace(find=no_backend, NoBackendError=NoBackendError)
    )
    rows, notes = devices.discover((devices.probe_usb,))
    assert rows == [] and "libusb-1.0-0" in notes[0]


@pytest.mark.parametrize("probe", devices.PROBES)
def test_each_probe_returns_rows_and_notes(probe: devices.Probe) -> None:
    rows, notes = devices.discover((probe,))
    assert isinstance(rows, list) and isinstance(notes, list)
