"""`rig devices`: list connected devices and the driver that fits each.

Each probe is independent: a missing optional library (gphoto2, seabreeze) or system library
(libusb) becomes a note under the table, never a crash; no hardware prints "none found".
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Found:
    kind: str
    address: str
    device: str
    driver: str


Probe = Callable[[], tuple[list[Found], list[str]]]


def _driver_for(vid: int | None, pid: int | None) -> tuple[str, str] | None:
    from drivers.registry import OCEAN_VID, USB_IDS

    if vid is None or pid is None:
        return None
    if vid == OCEAN_VID:
        return "seabreeze", "Ocean Insight spectrometer"
    return USB_IDS.get((vid, pid))


def probe_serial() -> tuple[list[Found], list[str]]:
    from serial.tools import list_ports

    rows = []
    for port in list_ports.comports():
        if port.vid is None and port.hwid == "n/a":
            continue  # a motherboard UART with nothing behind it
        match = _driver_for(port.vid, port.pid)
        ids = f" [{port.vid:04x}:{port.pid:04x}]" if port.vid is not None else ""
        rows.append(
            Found(
                "serial",
                port.device,
                f"{port.description or port.name}{ids}",
                match[0] if match else "unknown (rgbcw-serial?)",
            )
        )
    return rows, []


def probe_hid() -> tuple[list[Found], list[str]]:
    try:
        hid = importlib.import_module("hid")
    except ImportError as error:
        return [], [f"HID not probed: hidapi cannot be loaded ({error})"]
    rows = []
    for info in hid.enumerate():
        match = _driver_for(info.get("vendor_id"), info.get("product_id"))
        if match:
            path = info.get("path", b"")
            rows.append(
                Found(
                    "hid",
                    path.decode(errors="replace") if isinstance(path, bytes) else str(path),
                    f"{info.get('product_string') or match[1]} "
                    f"[{info['vendor_id']:04x}:{info['product_id']:04x}]",
                    match[0],
                )
            )
    return rows, []


def probe_usb() -> tuple[list[Found], list[str]]:
    from drivers.lights.udmx import UDMX_PRODUCT
    from drivers.transports.usb_device import string_descriptor

    usb_core = importlib.import_module("usb.core")
    try:
        devices = list(usb_core.find(find_all=True))
    except usb_core.NoBackendError:
        return [], [
            "USB not probed: libusb is missing (Debian/Ubuntu: `sudo apt install libusb-1.0-0`)"
        ]
    rows = []
    for dev in devices:
        match = _driver_for(dev.idVendor, dev.idProduct)
        if match and match[0] in {"udmx", "seabreeze"}:
            product = string_descriptor(dev, "product")
            if match[0] == "udmx" and product not in (None, UDMX_PRODUCT):
                continue  # another V-USB device on the shared id (e.g. a USBasp programmer)
            address = f"bus {dev.bus} device {dev.address}"
            ids = f"[{dev.idVendor:04x}:{dev.idProduct:04x}]"
            rows.append(Found("usb", address, f"{product or match[1]} {ids}", match[0]))
    return rows, []


def probe_cameras() -> tuple[list[Found], list[str]]:
    try:
        gp = importlib.import_module("gphoto2")
    except ImportError:
        from core.install import install_command

        hint = install_command("gphoto2")
        return [], [f"cameras not probed: `{hint}` adds tethered cameras"]
    try:
        detected = list(gp.Camera.autodetect().items())  # (name, port) pairs
    except gp.GPhoto2Error as error:
        return [], [f"camera probe failed: {error}"]
    return [Found("camera", port, name, "gphoto2") for name, port in detected], []


def probe_spectrometers() -> tuple[list[Found], list[str]]:
    try:
        spectrometers = importlib.import_module("seabreeze.spectrometers")
    except ImportError:
        from core.install import install_command

        hint = install_command("seabreeze")
        return [], [f"spectrometers not probed: `{hint}` adds Ocean ones"]
    try:
        devices = spectrometers.list_devices()
    except Exception as error:  # backend-specific SeaBreezeError types
        return [], [f"spectrometer probe failed: {error}"]
    return [
        Found("spectrometer", str(d.serial_number), str(d.model), "seabreeze") for d in devices
    ], []


PROBES: tuple[Probe, ...] = (
    probe_serial,
    probe_hid,
    probe_usb,
    probe_cameras,
    probe_spectrometers,
)


def discover(probes: tuple[Probe, ...] = PROBES) -> tuple[list[Found], list[str]]:
    rows: list[Found] = []
    notes: list[str] = []
    for probe in probes:
        try:
            found, said = probe()
        except Exception as error:  # one broken probe must not hide the others
            found, said = [], [f"{probe.__name__} failed: {type(error).__name__}: {error}"]
        rows += found
        notes += said
    # the same device seen as USB and as a spectrometer: keep one line per address
    unique = {(r.kind, r.address): r for r in rows}
    return list(unique.values()), notes


def run(args: argparse.Namespace) -> int:
    from rich.table import Table

    from rig.console import console as plain_console

    rows, notes = discover()
    console = plain_console()
    if rows:
        table = Table(title="Connected devices")
        for column in ("kind", "address", "device", "driver"):
            table.add_column(column)
        for row in rows:
            table.add_row(row.kind, row.address, row.device, row.driver)
        console.print(table)
    else:
        console.print("none found")
    for note in notes:
        console.print(f"note: {note}")
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "devices", help="list connected devices and the driver that fits each"
    )
    parser.set_defaults(func=run)
