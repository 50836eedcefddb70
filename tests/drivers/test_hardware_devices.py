"""Tests against real devices, skipped unless named with ``--device KIND=ADDRESS``; kinds:
rgbcw, enttec (serial ports), udmx, k8062, magic-home (IP), camera (gphoto2 port or empty),
spectrometer (serial or empty), projector (display index). See docs/usage-drivers.md."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from drivers.registry import open_camera, open_light, open_projector, open_spectrometer

pytestmark = pytest.mark.hardware
RGBCW = {"r": 1, "g": 2, "b": 3, "c": 4, "w": 5}


def address(devices: dict[str, str], kind: str) -> str:
    if kind not in devices:
        pytest.skip(f"no --device {kind}=ADDRESS given")
    return devices[kind]


def cycle(light) -> None:
    """Every channel on alone for a moment, then off; the person watches the fixture."""
    try:
        for channel in light.channels:
            light.set_levels({channel: 0.3})
            time.sleep(0.3)
        light.off()
    finally:
        light.close()


def test_rgbcw_serial_controller(devices: dict[str, str]) -> None:
    port = address(devices, "rgbcw")
    light = open_light({"driver": "rgbcw-serial", "transport": {"port": port, "timeout_s": 2}})
    assert light.describe()["device"]["model"]
    cycle(light)


def test_enttec_dmx_pro(devices: dict[str, str]) -> None:
    port = address(devices, "enttec")
    light = open_light({"driver": "enttec-dmx-pro", "transport": {"port": port}, "channels": RGBCW})
    assert light.describe()["serial"]
    cycle(light)


def test_udmx(devices: dict[str, str]) -> None:
    address(devices, "udmx")
    cycle(open_light({"driver": "udmx", "channels": RGBCW}))


def test_velleman_k8062(devices: dict[str, str]) -> None:
    address(devices, "k8062")
    cycle(open_light({"driver": "velleman-k8062", "channels": RGBCW}))


def test_magic_home_bulb(devices: dict[str, str]) -> None:
    host = address(devices, "magic-home")
    light = open_light(
        {"driver": "magic-home", "transport": {"host": host}, "exclusive_white": True}
    )
    assert light.describe()["model_num"]
    cycle(light)


def test_gphoto2_camera_captures_a_raw(devices: dict[str, str], tmp_path: Path) -> None:
    port = address(devices, "camera")
    camera = open_camera({"driver": "gphoto2", **({"port": port} if port else {})})
    try:
        frame = camera.capture(tmp_path, "hw0000")
    finally:
        camera.close()
    assert frame.paths[0].stat().st_size > 100_000 and frame.exposure_s > 0


def test_seabreeze_spectrometer(devices: dict[str, str]) -> None:
    serial = address(devices, "spectrometer")
    spectrometer = open_spectrometer(
        {"driver": "seabreeze", **({"serial": serial} if serial else {})}
    )
    try:
        spectrometer.auto_range()  # type: ignore[attr-defined]
        spectrum = spectrometer.measure()
    finally:
        spectrometer.close()
    assert spectrum.values.shape == spectrum.wavelengths_nm.shape


def test_projector_display(devices: dict[str, str]) -> None:
    display = address(devices, "projector")
    projector = open_projector({"driver": "pygame", "display": int(display or 0)})
    try:
        from drivers.projectors.patterns import gray_code_image

        projector.show(gray_code_image(projector.width, projector.height, "col", 0))
        time.sleep(1)
    finally:
        projector.close()
