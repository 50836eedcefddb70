"""The manual light, and opening drivers by name from profile sections."""

from __future__ import annotations

import json
import re

import pytest

from core.errors import RigError
from core.install import install_command
from drivers.lights.enttec import EnttecDmxPro
from drivers.lights.manual import ManualLight
from drivers.lights.rgbcw_emulator import serve_pty
from drivers.protocols import LightSource
from drivers.registry import list_driver_names, open_camera, open_light, open_spectrometer


def test_manual_light_asks_the_person() -> None:
    prompts: list[str] = []
    answers = iter(["", "", "q"])

    def ask(prompt: str) -> str:
        prompts.append(prompt)
        return next(answers)

    light = ManualLight(illuminations={"LED1": {"c": 1.0}}, ask=ask)
    assert isinstance(light, LightSource)
    light.set_illumination("LED1")
    light.set_levels({"r": 0.5})
    with pytest.raises(RigError, match="aborted"):
        light.off()
    assert "illumination 'LED1' (c=1.00)" in prompts[0]
    assert "r=0.50" in prompts[1]
    assert "off" in prompts[2]


def test_list_driver_names() -> None:
    assert list_driver_names("light") == [
        "dmx",
        "enttec-dmx-pro",
        "magic-home",
        "manual",
        "rgbcw-serial",
        "sim",
        "tuya",
        "udmx",
        "velleman-k8062",
    ]
    assert "gphoto2" in list_driver_names() and "seabreeze" in list_driver_names()


def test_unknown_driver_lists_the_known_ones() -> None:
    with pytest.raises(RigError, match="use one of: dmx, enttec-dmx-pro, magic-home, manual"):
        open_light({"driver": "philips-hue"})
    with pytest.raises(RigError, match="no `driver:`"):
        open_light({"channels": {}})


def test_registry_opens_a_replayed_enttec(tmp_path) -> None:
    recording = tmp_path / "enttec.jsonl"
    recording.write_text(
        '{"request": "7e0a0000e7", "reply": "7e0a040078563412e7"}\n'
        '{"request": "7e0302000000e7", "reply": "7e0305002c01090128e7"}\n'
    )
    light = open_light(
        {
            "driver": "enttec-dmx-pro",
            "transport": {"type": "replay", "file": str(recording)},
            "channels": {"r": 1, "g": 2, "b": 3, "c": 4, "w": 5},
            "illuminations": {"LED1": {"c": 1.0}},
            "settle_s": 0.0,
        }
    )
    assert isinstance(light, EnttecDmxPro)
    assert light.describe()["serial"] == "12345678"


def test_registry_accepts_the_shipped_dmx_profile_shape(tmp_path) -> None:
    """profiles/dmx-gphoto2.yaml: `driver: dmx`, `transport: {kind: ...}`, channel list
    from `start_address`; the capture code adds the profile's illuminations."""
    frame = bytearray(512)
    frame[9] = 255  # w is the 4th channel from address 7 -> DMX 10
    recording = tmp_path / "dmx.jsonl"
    message = bytes([0x7E, 6, 1, 2, 0]) + frame + b"\xe7"
    recording.write_text(json.dumps({"request": message.hex(), "reply": ""}) + "\n")
    light = open_light(
        {
            "driver": "dmx",
            "transport": {"kind": "replay", "file": str(recording)},
            "start_address": 7,
            "channels": ["r", "g", "b", "w"],
            "settle_s": 0.0,
            "identify": False,
            "illuminations": {"white": {"w": 1.0}},
        }
    )
    assert light.describe()["dmx_addresses"] == {"r": 7, "g": 8, "b": 9, "w": 10}
    light.set_illumination("white")
    light.transport.assert_done()  # type: ignore[attr-defined]


def test_driver_names_for_profile_validation() -> None:
    from drivers.registry import DRIVERS

    assert set(DRIVERS) == {"light", "camera", "projector", "spectrometer"}
    assert "dmx" in DRIVERS["light"] and "gphoto2" in DRIVERS["camera"]
    assert DRIVERS["projector"] == ("pygame", "sim")
    assert all("sim" in names for names in DRIVERS.values())


def test_driver_sim_resolves_through_the_registry_one_world_per_device_set() -> None:
    from drivers.device_set import DeviceSet
    from drivers.protocols import (
        Camera,
        GroundTruthSource,
        SelfPositioning,
        Spectrometer,
        WhiteReferenceSource,
    )
    from drivers.registry import open_projector

    pytest.importorskip("drivers.sim")
    shared = DeviceSet(views=3, illuminations={"LED1": {"c": 1.0}})
    camera = open_camera({"driver": "sim"}, shared)
    light = open_light({"driver": "sim"}, shared)
    projector = open_projector({"driver": "sim"}, shared)
    spectrometer = open_spectrometer({"driver": "sim"}, shared)
    assert isinstance(camera, Camera) and isinstance(light, LightSource)
    assert isinstance(spectrometer, Spectrometer)
    # one simulated world per device set: the camera renders the light and projector opened
    assert camera.light is light and camera.projector is projector  # type: ignore[attr-defined]
    assert light.illuminations == {"LED1": {"c": 1.0}}
    assert len(camera.view_directions()) == 3  # type: ignore[attr-defined]
    for capability in (SelfPositioning, GroundTruthSource, WhiteReferenceSource):
        assert isinstance(camera, capability) and isinstance(light, capability)
    other = open_camera({"driver": "sim"}, DeviceSet())
    assert other.light is not light  # type: ignore[attr-defined]


def test_registry_opens_the_serial_text_light_on_a_pty() -> None:
    with serve_pty() as (port, emulator):
        light = open_light(
            {
                "driver": "rgbcw-serial",
                "transport": {"port": port, "timeout_s": 2},
                "illuminations": {"LED1": {"c": 1.0}},
            }
        )
        light.set_illumination("LED1")
        light.close()
    assert emulator.levels["c"] == 1.0


def test_bad_driver_settings_are_a_rig_error() -> None:
    with pytest.raises(RigError, match="light driver 'manual': key 'colour' is not known"):
        open_light({"driver": "manual", "colour": "blue"})
    with pytest.raises(RigError, match="tuya light needs device_id"):
        open_light({"driver": "tuya"})


def test_tuya_without_tinytuya_names_the_extra(monkeypatch) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "tinytuya", None)  # import fails as if not installed
    with pytest.raises(RigError, match=re.escape(install_command("tuya"))):
        open_light({"driver": "tuya", "device_id": "x", "address": "10.0.0.2", "local_key": "k"})


@pytest.mark.parametrize("key", ["device_id", "local_key"])
def test_tuya_refuses_the_shipped_placeholders_and_names_the_guide(key: str) -> None:
    options = {"driver": "tuya", "device_id": "bf12", "address": "10.0.0.2", "local_key": "k"}
    options[key] = f"REPLACE-WITH-{key.upper().replace('_', '-')}"
    with pytest.raises(RigError, match=f"{key} is still the shipped placeholder") as error:
        open_light(options)
    assert "tinytuya wizard" in str(error.value) and "docs/first-scan.md#" in str(error.value)


def test_file_import_spectrometer_from_the_registry() -> None:
    spectrometer = open_spectrometer({"driver": "file-import", "fmt": "csv"})
    assert spectrometer.describe()["format"] == "csv"
