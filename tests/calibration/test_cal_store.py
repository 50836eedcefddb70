"""Calibration store: versions, provenance, integrity, snapshots, the default store."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from calibration import defaults
from calibration.grid import DEFAULT_GRID, SpectralGrid
from calibration.store import CalibrationStore
from core.errors import RigError

W = np.arange(380.0, 781.0, 5.0)


def spd(peak: float) -> np.ndarray:
    return np.exp(-0.5 * ((W - peak) / 25) ** 2)


def test_add_read_and_version(tmp_path: Path) -> None:
    store = CalibrationStore(tmp_path / "s")
    e1 = store.add_light("LED1", W, spd(450), {"device": "bulb", "serial": "A1", "notes": None})
    assert (e1.version, e1.file) == (1, "lights/LED1.v1.csv")
    assert e1.provenance == {"device": "bulb", "serial": "A1"}
    header = (tmp_path / "s" / e1.file).read_text().splitlines()[0]
    assert header == "wavelength_nm,power"
    e2 = store.add_light("LED1", W, spd(600), {"device": "bulb"})
    assert e2.version == 2 and (tmp_path / "s" / e1.file).exists()  # old one kept
    grid = DEFAULT_GRID.wavelengths
    assert grid[np.argmax(store.light_spd("LED1"))] == 600
    assert grid[np.argmax(store.light_spd("LED1", version=1))] == 450
    # a fresh object reads the same index
    again = CalibrationStore(tmp_path / "s")
    assert [(e.name, e.version) for e in again.entries()] == [("LED1", 1), ("LED1", 2)]
    assert [e.version for e in again.entries(all_versions=False)] == [2]
    assert store.light_spd("LED1", SpectralGrid(400, 700, 5)).shape == (61,)
    # names that slug to the same file name get their own files
    spaced = store.add_light("bulb a", W, spd(500), {})
    underscored = store.add_light("bulb_a", W, spd(520), {})
    assert spaced.file == "lights/bulb_a.v1.csv" and underscored.file != spaced.file
    assert grid[np.argmax(store.light_spd("bulb_a"))] == 520


def test_camera_entries(tmp_path: Path) -> None:
    store = CalibrationStore(tmp_path)
    rgb = np.stack([spd(600), spd(530), spd(460)], axis=1)
    e = store.add_camera("cam/test", W, rgb, {"instrument": "monochromator"})
    assert e.file == "cameras/cam__test.v1.csv"
    header = (tmp_path / e.file).read_text().splitlines()[0]
    assert header == "wavelength_nm,R,G,B"
    c = store.camera("cam/test")
    assert c.shape == (31, 3)
    with pytest.raises(RigError, match="needs 3"):
        store.add_camera("bad", W, rgb[:, :2], {})
    with pytest.raises(RigError, match="no light entry named 'cam/test'"):
        store.light_spd("cam/test")
    with pytest.raises(RigError, match="already names a camera"):
        store.add_light("cam/test", W, spd(500), {})


def test_remove_and_errors(tmp_path: Path) -> None:
    store = CalibrationStore(tmp_path)
    store.add_light("L", W, spd(500), {})
    store.add_light("L", W, spd(520), {})
    store.remove("L", 1)
    assert not (tmp_path / "lights/L.v1.csv").exists()
    assert [e.version for e in store.entries()] == [2]
    v3 = store.add_light("L", W, spd(540), {})
    assert v3.version == 3  # numbers are never reused
    with pytest.raises(RigError, match="has no version 7"):
        store.light_spd("L", version=7)
    with pytest.raises(RigError, match="invalid calibration entry name"):
        store.add_light("../evil", W, spd(500), {})
    store.remove("L")
    assert store.entries() == []
    with pytest.raises(RigError, match="no calibration entry named 'L'"):
        store.remove("L")


def test_edited_file_is_detected(tmp_path: Path) -> None:
    store = CalibrationStore(tmp_path)
    e = store.add_light("L", W, spd(500), {})
    path = tmp_path / e.file
    path.write_text(
        path.read_text().replace("wavelength_nm,power\n380", "wavelength_nm,power\n381")
    )
    with pytest.raises(RigError, match="modified after it was added"):
        store.light_spd("L")
    path.unlink()
    with pytest.raises(RigError, match="is missing"):
        store.light_spd("L")


def test_malformed_index(tmp_path: Path) -> None:
    (tmp_path / "index.yaml").write_text("format: [unclosed\n")
    with pytest.raises(RigError, match="not valid YAML"):
        CalibrationStore(tmp_path)
    (tmp_path / "index.yaml").write_text("format: something-else\n")
    with pytest.raises(RigError, match="not a spectral-rig calibration index"):
        CalibrationStore(tmp_path)
    (tmp_path / "index.yaml").write_text(
        yaml.safe_dump({"format": "spectral-rig-calibration/1", "entries": [{"name": "x"}]})
    )
    with pytest.raises(RigError, match="entry 1 is malformed"):
        CalibrationStore(tmp_path)
    record = {
        "name": "L",
        "kind": "light",
        "version": "two",
        "file": "lights/L.v1.csv",
        "added": "2026-01-01",
        "sha256": "0" * 64,
        "provenance": {},
    }
    (tmp_path / "index.yaml").write_text(
        yaml.safe_dump({"format": "spectral-rig-calibration/1", "entries": [record]})
    )
    with pytest.raises(RigError, match="'L' has version 'two'"):
        CalibrationStore(tmp_path)


def test_default_store_and_snapshot(tmp_path: Path) -> None:
    store = CalibrationStore.create_default(tmp_path / "default")
    names = store.names()
    for expected in ("bulb/r", "bulb/g", "bulb/b", "bulb/c", "bulb/w", "LED1", "LED2", "LED3"):
        assert expected in names
    for cam in defaults.camera_names():
        np.testing.assert_allclose(store.camera(cam), defaults.camera_sensitivity(cam), atol=1e-6)
    np.testing.assert_allclose(
        store.light_spd("bulb/w"), defaults.rgbcw_channel_spds()["w"], rtol=1e-6
    )
    assert "Ohno 2005" in store.entry("bulb/r").provenance["source"]
    assert store.entry("LED3").provenance["mix"] == {"r": 1.0, "g": 1.0, "b": 1.0}
    snap = store.copy_to(tmp_path / "session" / "calibration")
    assert snap.names() == names
    np.testing.assert_array_equal(snap.light_spd("LED2"), store.light_spd("LED2"))
    with pytest.raises(RigError, match="not empty"):
        store.copy_to(tmp_path / "session" / "calibration")
    with pytest.raises(RigError, match="already holds a calibration store"):
        CalibrationStore.create_default(tmp_path / "default")
    empty = CalibrationStore(tmp_path / "never-written").copy_to(tmp_path / "empty-snapshot")
    assert empty.names() == [] and (tmp_path / "empty-snapshot" / "index.yaml").exists()
    (store.root / store.entry("LED1").file).unlink()
    with pytest.raises(RigError, match="cannot copy calibration file .*'LED1' v1"):
        store.copy_to(tmp_path / "session2")
