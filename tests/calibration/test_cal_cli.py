"""`rig calibrate` end to end through the real CLI entry point."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cal_samples import WAVELENGTHS, led, oceanview_text, spectrawiz_text

from calibration.basis import SpectralBasis
from calibration.store import CalibrationStore
from rig.cli import main


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SPECTRAL_RIG_STORE", str(tmp_path / "store"))
    return tmp_path


def test_select_and_basis_work_out_of_the_box(
    workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["calibrate", "select", "--noise", "0"]) == 0
    out = capsys.readouterr().out
    assert "LED1 + LED2 + LED3" in out and "best with 2" in out
    assert (workdir / "illumination-selection.png").stat().st_size > 10_000
    assert main(["calibrate", "basis", "--out", "b.npz"]) == 0
    out = capsys.readouterr().out
    assert "8 components explain 99." in out
    assert SpectralBasis.load(workdir / "b.npz").B.shape == (31, 8)
    assert (workdir / "basis.png").exists()


def test_basis_from_munsell(
    workdir: Path, shared_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = shared_data / "reflectance" / "munsell_matt_1269_380_780_5nm.csv"
    assert main(["calibrate", "basis", "--from", str(src), "--plot", "m.png"]) == 0
    assert "8 components explain 99.976 %" in capsys.readouterr().out
    assert (workdir / "m.png").exists()


def test_store_workflow(workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["calibrate", "list"]) == 2  # no store yet: clear error
    assert "rig calibrate init-store" in capsys.readouterr().err
    assert main(["calibrate", "init-store"]) == 0
    assert main(["calibrate", "list"]) == 0
    assert "bulb/w" in capsys.readouterr().out

    ov = workdir / "LED1.txt"
    ov.write_text(oceanview_text(WAVELENGTHS, led(WAVELENGTHS)))
    args = ["calibrate", "import", str(ov), "--kind", "light", "--name", "LED1"]
    assert main([*args, "--device", "Haodeng WH018", "--notes", "warm-up 10 min"]) == 0
    assert "version 2" in capsys.readouterr().out
    store = CalibrationStore(workdir / "store")
    entry = store.entry("LED1")
    assert entry.version == 2 and entry.provenance["serial"] == "FLMS01234"
    assert entry.provenance["device"] == "Haodeng WH018"
    assert entry.provenance["integration_time_ms"] == pytest.approx(100.0)
    assert store.entry("LED1", 1).provenance["mix"] == {"c": 1.0}  # old version untouched

    w = np.arange(300.0, 850.0, 0.5)
    sw = workdir / "LED2.IRR"
    sw.write_text(spectrawiz_text(w, led(w)))
    assert main(["calibrate", "import", str(sw), "--kind", "light", "--name", "LED2"]) == 0
    cam = workdir / "cam.csv"
    cam.write_text(
        "wavelength_nm,R,G,B\n"
        + "\n".join(f"{x},{led(x)},{led(x + 80)},{led(x + 160)}" for x in range(380, 781, 5))
    )
    assert main(["calibrate", "import", str(cam), "--kind", "camera", "--name", "mycam"]) == 0
    assert main(["calibrate", "import", "colour:FL2", "--kind", "light", "--name", "FL2"]) == 0

    assert main(["calibrate", "show", "LED1", "--plot", "led1.png"]) == 0
    out = capsys.readouterr().out
    assert "FLMS01234" in out and (workdir / "led1.png").exists()
    assert main(["calibrate", "show", "mycam"]) == 0
    assert (workdir / "mycam.v1.png").exists()

    sel = ["calibrate", "select", "--lights", "LED1,LED2,FL2", "--camera", "mycam", "--top", "3"]
    assert main([*sel, "--plot", "sel.png"]) == 0
    out = capsys.readouterr().out
    assert "mycam" in out and "best with 3: LED1 + LED2 + FL2" in out
    assert (workdir / "sel.png").exists()
    assert main(["calibrate", "select", "--mixtures", "--max-size", "1"]) == 0

    assert main(["calibrate", "remove", "LED1"]) == 2  # two versions: must say which
    assert "--version" in capsys.readouterr().err
    assert main(["calibrate", "remove", "LED1", "--version", "1"]) == 0
    assert [
        e.version for e in CalibrationStore(workdir / "store").entries() if e.name == "LED1"
    ] == [2]


def test_bad_import_is_one_line_error(workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = workdir / "bad.csv"
    bad.write_text("wavelength_nm,power\n400,1\n500,1\n450,1\n600,1\n700,1\n")
    rc = main(["calibrate", "import", str(bad), "--kind", "light", "--name", "x"])
    err = capsys.readouterr().err
    assert rc == 2 and "not increasing" in err and "Traceback" not in err
    assert main(["calibrate", "select", "--top", "0"]) == 2
    assert "--top 0 must be at least 1" in capsys.readouterr().err


def test_parser_constants_match_the_library() -> None:
    from calibration import defaults, importers, store
    from rig.commands import calibrate

    assert calibrate.FORMATS == importers.FORMATS
    assert calibrate.DEFAULT_CAMERA == defaults.DEFAULT_CAMERA
    assert calibrate.ENV_STORE == store.ENV_STORE
