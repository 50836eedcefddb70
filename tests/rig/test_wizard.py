"""The calibration wizard on the simulated rig writes a store that reproduces the sim's true
light SPDs in the forward model's units, and a capture can use it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from calibration import defaults
from calibration.store import CalibrationStore
from core.session import Session
from rig.capture import run_capture
from rig.cli import main

pytest.importorskip("drivers.sim")
PROFILE = Path(__file__).with_name("sim-small.yaml")


def true_spd(name: str) -> np.ndarray:
    levels = defaults.default_illuminations()[name]
    return defaults.illumination_spd(levels, defaults.rgbcw_channel_spds())


def relative_error(measured: np.ndarray, truth: np.ndarray) -> float:
    """Error over the band where the light has power (the noise floor elsewhere is moot)."""
    band = truth > 0.05 * truth.max()
    return float(np.abs(measured[band] - truth[band]).mean() / truth[band].mean())


def test_wizard_runs_through_on_the_sim_and_writes_a_usable_store(tmp_path: Path) -> None:
    store_dir = tmp_path / "store"
    code = main(
        ["calibrate", "wizard", "--yes", "--profile", str(PROFILE), "--store", str(store_dir)]
    )
    assert code == 0
    store = CalibrationStore(store_dir)
    assert set(store.names("light")) == {"LED1", "LED2", "LED3"}
    assert store.names("camera") == ["Canon EOS 5D Mark II"]
    for name in ("LED1", "LED2", "LED3"):
        measured, truth = store.light_spd(name), true_spd(name)
        assert relative_error(measured, truth) < 0.15  # narrow LED peaks: 0.5 nm -> 10 nm bins
        camera = defaults.camera_sensitivity()
        np.testing.assert_allclose(camera.T @ measured, camera.T @ truth, rtol=0.05)
        prov = store.entry(name).provenance
        assert "SimSpec" in prov["instrument"] or "simulated" in prov["instrument"]
        assert prov["radiometric_scale"] > 0 and "white reference" in prov["notes"]
    plots = sorted(p.name for p in (store_dir / "plots").iterdir())
    assert "illumination-selection.png" in plots and "spd-LED1.v1.png" in plots
    # a capture profile pointing at the new store snapshots it into the session
    data = yaml.safe_load(PROFILE.read_text())
    data["calibration"]["store"] = str(store_dir)
    data["plan"]["views"] = 1
    profile_path = tmp_path / "rig.yaml"
    profile_path.write_text(yaml.safe_dump(data))
    out = run_capture(str(profile_path), tmp_path / "session", yes=True)
    snapshot = CalibrationStore(Session.open(out).calibration_dir)
    np.testing.assert_allclose(snapshot.light_spd("LED2"), store.light_spd("LED2"))


def test_wizard_scales_an_imported_spd_of_arbitrary_units(tmp_path: Path) -> None:
    csv = tmp_path / "led2.csv"
    grid = np.arange(400, 701, 5.0)
    spd = np.interp(grid, np.arange(400, 701, 10.0), true_spd("LED2")) * 1234.0
    csv.write_text(
        "wavelength_nm,power\n"
        + "".join(f"{w:g},{v:.6g}\n" for w, v in zip(grid, spd, strict=True))
    )
    store_dir = tmp_path / "store"
    code = main(
        [
            "calibrate",
            "wizard",
            "--yes",
            "--profile",
            str(PROFILE),
            "--store",
            str(store_dir),
            "--import",
            f"LED2={csv}",
            "--camera",
            "Canon EOS 5D Mark II",
        ]
    )
    assert code == 0
    store = CalibrationStore(store_dir)
    assert relative_error(store.light_spd("LED2"), true_spd("LED2")) < 0.05
    assert "imported" in store.entry("LED2").provenance["source"]


def test_wizard_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = [
        "calibrate",
        "wizard",
        "--yes",
        "--profile",
        str(PROFILE),
        "--store",
        str(tmp_path / "s"),
    ]
    assert main([*args, "--import", "LED9=x.csv"]) == 2
    assert "LED9" in capsys.readouterr().err
    assert main([*args, "--reference-region", "1,2"]) == 2
    assert "X0,Y0,X1,Y1" in capsys.readouterr().err


def test_wizard_interactive_prompts_step_by_step(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from rich.console import Console

    asked: list[str] = []

    def answer(self: Console, prompt: str = "", **_: object) -> str:
        asked.append(prompt)
        return "Sigma SD Merrill" if prompt.startswith("3/5") else ""

    monkeypatch.setattr(Console, "input", answer)
    store_dir = tmp_path / "store"
    assert main(["calibrate", "wizard", "--profile", str(PROFILE), "--store", str(store_dir)]) == 0
    assert [p[:3] for p in asked] == ["1/5", "2/5", "2/5", "2/5", "3/5"]
    assert "LED2" in asked[2]
    prov = CalibrationStore(store_dir).entry("Canon EOS 5D Mark II").provenance
    assert "Sigma SD Merrill" in prov["notes"]  # the person's choice, under the profile's name
