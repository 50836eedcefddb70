"""Flat field: the fit recovers a known fall-off through texture and noise, the store keeps it
with its hash checked, and a real lens in lensfun's database falls off monotonically."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from calibration.flat_field import FlatField, card_shading, fit_flat_field
from calibration.store import CalibrationStore
from core.errors import RigError

TRUE_K = np.array([[-0.5, 0.1, 0.0], [-0.4, 0.05, 0.0], [-0.3, 0.0, 0.02]])


def true_flat() -> FlatField:
    return FlatField(TRUE_K, 4 / 3)


def test_fit_recovers_the_fall_off_through_texture_and_noise() -> None:
    rng = np.random.default_rng(1)
    gain = true_flat().gain(320, 240)
    shading = card_shading(320, 240, 400.0, 0.4, (0.1, 0.0, 0.0))
    frames = []
    for _ in range(4):
        texture = 1 + 0.03 * rng.standard_normal((240, 320, 1))
        frames.append(0.4 * gain * shading[..., None] * texture
                      + 0.005 * rng.standard_normal((240, 320, 3)))
    frames[0][100:110, 50:60] = 0.0  # a speck of dust on one frame only
    valid = [np.ones((240, 320), bool) for _ in frames]
    valid[1][:20, :20] = False  # a saturated corner
    flat = fit_flat_field(frames, valid, shading)
    assert np.abs(flat.gain(320, 240) - gain).max() < 0.01
    assert flat.gain(320, 240)[120, 160] == pytest.approx(1.0, abs=1e-3)
    # the same frames without the light's geometry read darker corners than the lens's
    assert fit_flat_field(frames, valid).corner_gain()[1] < flat.corner_gain()[1] - 0.1


def test_card_shading_is_cos_cubed_for_a_light_at_the_camera() -> None:
    shading = card_shading(200, 100, 100.0, 0.5)
    x = (np.arange(200) + 0.5 - 100) / 100.0
    cos = 1 / np.sqrt(1 + x**2 + (0.5 / 100) ** 2)  # row 50's centre is 0.5 px off the axis
    np.testing.assert_allclose(shading[50], cos**3, rtol=1e-9)
    with pytest.raises(RigError, match="does not light"):
        card_shading(10, 10, 10.0, 0.5, (0.0, 0.0, 1.0))


def test_gain_refuses_another_aspect_and_round_trips() -> None:
    flat = true_flat()
    with pytest.raises(RigError, match="aspect"):
        flat.gain(300, 300)
    again = FlatField.from_dict(flat.to_dict(), "x")
    np.testing.assert_allclose(again.gain(64, 48), flat.gain(64, 48))
    with pytest.raises(RigError, match="not a flat field"):
        FlatField.from_dict({"format": "other"}, "x.yaml")
    with pytest.raises(RigError, match="malformed"):
        FlatField.from_dict({**flat.to_dict(), "coefficients": {"R": [1]}}, "x.yaml")


def test_store_keeps_versions_checks_the_hash_and_snapshots(tmp_path: Path) -> None:
    store = CalibrationStore(tmp_path / "store")
    first = store.add_flat_field("flat/cam", true_flat(), {"source": "test"})
    second = store.add_flat_field("flat/cam", FlatField(TRUE_K * 0.5, 4 / 3), {})
    assert (first.version, second.version, first.file) == (1, 2, "flat_fields/flat__cam.v1.yaml")
    entry, flat = CalibrationStore(store.root).flat_field("flat/cam", 1)
    np.testing.assert_allclose(flat.coefficients, TRUE_K)
    assert store.names("flat_field") == ["flat/cam"]
    with pytest.raises(RigError, match="flat field, not a spectrum"):
        store.read_native(entry)
    snapshot = store.copy_to(tmp_path / "session" / "calibration")
    assert snapshot.flat_field("flat/cam")[0].version == 2
    (store.root / first.file).write_text("format: x\n")
    with pytest.raises(RigError, match="sha256"):
        store.flat_field("flat/cam", 1)


def test_lensfun_profile_of_a_real_lens_falls_off_monotonically() -> None:
    pytest.importorskip("lensfunpy")
    from calibration.lensfun import lensfun_flat_field

    wide = lensfun_flat_field(
        "Canon Canon EOS 5D Mark II", "Canon EF 50mm f/1.4 USM", 50.0, 1.4, (5616, 3744)
    )
    stopped = lensfun_flat_field(
        "Canon Canon EOS 5D Mark II", "Canon EF 50mm f/1.4 USM", 50.0, 4.0, (5616, 3744)
    )
    step = np.arange(200)
    diagonal = wide.gain(600, 400)[199 - step, 300 + step * 3 // 2, 1]  # centre -> corner
    assert diagonal[0] == pytest.approx(1.0, abs=1e-3)
    assert np.all(np.diff(diagonal) < 0)
    assert 0.1 < wide.corner_gain()[1] < 0.5  # wide open: over a stop at the corners
    assert wide.corner_gain()[1] < stopped.corner_gain()[1] < 1.0
    assert wide.method == "lensfun" and "50mm" in wide.details["lensfun_lens"]
    with pytest.raises(RigError, match="no lens"):
        lensfun_flat_field("Canon Canon EOS 5D Mark II", "No Such Lens 3mm", 3, 2, (60, 40))
    with pytest.raises(RigError, match="no camera"):
        lensfun_flat_field("Nobody Nothing", "x", 3, 2, (60, 40))


def test_flat_field_command_from_lensfun_and_the_missing_extra(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from rig.cli import main

    pytest.importorskip("lensfunpy")
    store = ["--store", str(tmp_path / "store")]
    args = ["calibrate", "flat-field", "--lensfun", "Canon Canon EOS 5D Mark II",
            "--lens", "Canon EF 50mm f/1.4 USM", "--focal", "50", "--aperture", "2.8",
            "--size", "5616x3744", "--name", "flat/ef50", *store]
    assert main(args) == 0
    entry, flat = CalibrationStore(tmp_path / "store").flat_field("flat/ef50")
    assert flat.method == "lensfun" and "lensfun profile" in entry.provenance["source"]
    assert flat.corner_gain()[1] == pytest.approx(0.58, abs=0.01)
    assert main(["calibrate", "show", "flat/ef50", *store]) == 0
    assert "corner gain G" in capsys.readouterr().out
    assert main([*args[:-4], "--focal", "85", *store]) == 2
    assert "outside" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "lensfunpy", None)  # not installed
    assert main(args) == 2
    assert "lensfunpy is not installed" in capsys.readouterr().err
