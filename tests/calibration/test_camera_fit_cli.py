"""`rig calibrate camera --from-chart` end to end through the patch-CSV path: patch values of a
measured camera left out of the prior, under lamps measured into the store."""

from __future__ import annotations

import re
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from calibration import defaults
from calibration.camera_fit import simulate_patches
from calibration.camera_prior import DEFAULT_COMPONENTS, read_camspec
from calibration.store import CalibrationStore
from rig.cli import main
from rig.commands import calibrate_camera

HELD_OUT = "Canon 600D"
LAMPS = ("Osram.LED.10W.2700K", "Philips.Inc.50W.spot.halogen")


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, shared_data: Path) -> Path:
    """A store holding two lamps from the shared data, patch CSVs of the held-out camera under
    them and a camspec prior file without it."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SPECTRAL_RIG_STORE", str(tmp_path / "store"))
    assert main(["calibrate", "init-store"]) == 0
    table = shared_data / "spd" / "photobiologylamps_lamps_380_780_1nm.csv"
    for lamp in LAMPS:
        args = ["calibrate", "import", str(table), "--kind", "light", "--column", lamp]
        assert main([*args, "--name", lamp]) == 0
    camspec = (shared_data / "camera_ssf" / "camspec_database_27.txt").read_text().splitlines()
    at = camspec.index(HELD_OUT)
    (tmp_path / "prior.txt").write_text("\n".join(camspec[:at] + camspec[at + 4 :]) + "\n")
    store = CalibrationStore(tmp_path / "store")
    truth = read_camspec(shared_data / "camera_ssf").sensitivity(HELD_OUT)
    np.save(tmp_path / "truth.npy", truth)
    lamps = np.stack([store.light_spd(n) for n in LAMPS])
    patches = simulate_patches(truth, lamps, defaults.colorchecker_reflectances()[1])
    rng = np.random.default_rng(0)
    for p, photo in enumerate(patches * np.array([[[0.4]], [[0.15]]])):
        noisy = photo * (1 + 0.005 * rng.standard_normal(photo.shape))
        rows = "\n".join(",".join(f"{v:.6g}" for v in row) for row in noisy)
        (tmp_path / f"photo{p + 1}.csv").write_text(f"# photo {p + 1}\nR,G,B\n{rows}\n")
    return tmp_path


def test_a_camera_from_patch_csvs_lands_in_the_store(
    workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["calibrate", "camera", "--patches", "photo1.csv", "photo2.csv", "--lamp", *LAMPS]
    assert main([*args, "--name", "my camera", "--prior", "prior.txt"]) == 0
    out = capsys.readouterr().out
    assert "residual per patch" in out and "nearest training camera" in out
    assert "added camera 'my camera' version 1" in out
    store = CalibrationStore(workdir / "store")
    entry = store.entry("my camera", kind="camera")
    fitted = store.camera("my camera")
    truth = np.load(workdir / "truth.npy")
    assert np.sqrt(np.mean((fitted - truth) ** 2)) < 0.03  # measured 0.016
    assert fitted.max() == pytest.approx(1.0, abs=1e-6)
    prov = entry.provenance
    assert prov["lamps"] == [f"{n} v1" for n in LAMPS] and "ESTIMATE" in prov["notes"]
    assert prov["fit"]["prior_cameras"] == 26 and prov["fit"]["patch_error_max_percent"] < 3
    assert (workdir / "my_camera.chart-fit.png").stat().st_size > 20_000


def test_raw_photos_go_through_the_chart_reader(
    workdir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The RAW path calls ``reconstruct.chart.read_patches(path).rgb`` (the chart reader's
    interface), here a stand-in returning the CSVs' values."""
    read: list[Path] = []

    def read_patches(path: Path) -> SimpleNamespace:
        read.append(path)
        rgb = np.loadtxt(workdir / f"{path.stem}.csv", delimiter=",", skiprows=2)
        return SimpleNamespace(rgb=rgb, spread=np.zeros((24, 3)), corners=np.zeros((4, 2)))

    monkeypatch.setitem(
        sys.modules, "reconstruct.chart", SimpleNamespace(read_patches=read_patches)
    )
    args = ["calibrate", "camera", "--from-chart", "photo1.CR2", "photo2.CR2", "--lamp", *LAMPS]
    assert main([*args, "--name", "raw camera", "--prior", "prior.txt"]) == 0
    assert read == [Path("photo1.CR2"), Path("photo2.CR2")]
    store = CalibrationStore(workdir / "store")
    prov = store.entry("raw camera").provenance
    assert prov["method"] == "chart-fit" and prov["photos"][0].endswith("photo1.CR2")
    truth = np.load(workdir / "truth.npy")
    assert np.sqrt(np.mean((store.camera("raw camera") - truth) ** 2)) < 0.03


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--lamp", *LAMPS, LAMPS[0]], "3 --lamp names for 2 photos"),
        (["--lamp", "no such lamp"], "--lamp 'no such lamp' is not a light"),
        (["--lamp", LAMPS[0], "--white-level", "0.3"], "photo 1 patch .* is saturated"),
    ],
)
def test_bad_arguments_are_one_line(
    workdir: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    args = ["calibrate", "camera", "--patches", "photo1.csv", "photo2.csv", "--prior", "prior.txt"]
    assert main([*args, "--name", "x", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert re.search(message, err), err


def test_a_short_patch_file_and_a_thin_store_prior_are_refused(
    workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (workdir / "short.csv").write_text("1,2,3\n" * 23)
    args = ["calibrate", "camera", "--lamp", LAMPS[0], "--name", "x"]
    assert main([*args, "--patches", "short.csv", "--prior", "prior.txt"]) == 2
    assert "short.csv holds 23 patch rows" in capsys.readouterr().err
    assert main([*args, "--patches", "photo1.csv"]) == 2  # the store holds 3 cameras
    assert "pass --prior" in capsys.readouterr().err


def test_the_parser_default_matches_the_library() -> None:
    assert calibrate_camera.DEFAULT_COMPONENTS == DEFAULT_COMPONENTS
