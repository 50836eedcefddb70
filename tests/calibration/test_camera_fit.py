"""calibration.camera_fit: a held-out measured camera recovered from simulated chart photos, and
the one-line refusals of bad patch values and training sets."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calibration import defaults
from calibration.camera_fit import (
    PatchNoise,
    chart_coordinates,
    fit_camera,
    simulate_patches,
    validate_patches,
)
from calibration.camera_prior import TrainingSet, build_prior, read_camspec, training_set_from_store
from calibration.grid import DEFAULT_GRID
from calibration.importers import read_spectrum
from calibration.spectra import resample
from calibration.store import CalibrationStore
from core.errors import RigError

HELD_OUT = "Nikon D700"
LAMPS = ("Amaran.M9.LED.video.light.5500K", "Generic.Inc.bulb.60W")


@pytest.fixture(scope="module")
def training(shared_data: Path) -> TrainingSet:
    return read_camspec(shared_data / "camera_ssf" / "camspec_database_27.txt")


@pytest.fixture(scope="module")
def lamps(shared_data: Path) -> np.ndarray:
    table = read_spectrum(shared_data / "spd" / "photobiologylamps_lamps_380_780_1nm.csv")
    return np.stack(
        [
            resample(table.wavelengths_nm, table.column(n, "light"), DEFAULT_GRID, source=n)
            for n in LAMPS
        ]
    )


@pytest.fixture(scope="module")
def chart() -> np.ndarray:
    return defaults.colorchecker_reflectances()[1]


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


def test_the_camspec_database_reads_as_27_cameras_normalised_to_1(training: TrainingSet) -> None:
    assert len(training.names) == 27 and training.sensitivities.shape == (27, 31, 3)
    assert np.allclose(training.sensitivities.max(axis=(1, 2)), 1.0)
    assert HELD_OUT in training.names and HELD_OUT not in training.without(HELD_OUT).names


def test_a_held_out_camera_is_recovered_noise_free(
    training: TrainingSet, lamps: np.ndarray, chart: np.ndarray
) -> None:
    truth = training.sensitivity(HELD_OUT)
    prior = build_prior(training.without(HELD_OUT))
    patches = simulate_patches(truth, lamps, chart) * np.array([3.0, 0.2])[:, None, None]
    fit = fit_camera(patches, lamps, chart, prior)
    # measured 0.0153 (the prior's mean alone: 0.043)
    assert rmse(fit.sensitivity, truth) < 0.02
    assert rmse(prior.mean / prior.mean.max(), truth) > 0.04
    assert fit.sensitivity.max() == pytest.approx(1.0)
    assert fit.patch_error_percent().max() < 0.2  # measured 0.05 %
    # the exposures carry the photos' scale, the sensitivity does not
    raw = np.einsum("in,pn,nc->pic", chart, lamps, truth).max(axis=(1, 2))
    assert fit.exposure == pytest.approx(np.array([3.0, 0.2]) / raw, rel=0.05)
    assert np.all(fit.prior_distance < np.median(fit.training_distances) * 2)


def test_a_held_out_camera_is_recovered_from_noisy_patches_under_one_lamp(
    training: TrainingSet, lamps: np.ndarray, chart: np.ndarray
) -> None:
    truth = training.sensitivity(HELD_OUT)
    prior = build_prior(training.without(HELD_OUT))
    rng = np.random.default_rng(3)
    errors = []
    for _ in range(3):
        clean = simulate_patches(truth, lamps[:1], chart)
        noisy = clean * (1 + 0.01 * rng.standard_normal(clean.shape))
        fit = fit_camera(noisy, lamps[0], chart, prior, PatchNoise(relative=0.01))
        errors.append(rmse(fit.sensitivity, truth))
        assert np.all(fit.posterior_std > 0)
    assert max(errors) < 0.035  # measured 0.021-0.024


def test_light_falling_off_across_the_chart_is_fitted_not_bent_into_the_curves(
    training: TrainingSet, lamps: np.ndarray, chart: np.ndarray
) -> None:
    truth = training.sensitivity(HELD_OUT)
    prior = build_prior(training.without(HELD_OUT))
    falloff = 1.0 + chart_coordinates() @ np.array([0.05, -0.08])  # 0.755 to 1.245
    patches = simulate_patches(truth, lamps, chart) * falloff[None, :, None]
    fit = fit_camera(patches, lamps, chart, prior)
    assert fit.shading == pytest.approx(np.stack([falloff, falloff]), abs=0.01)
    assert rmse(fit.sensitivity, truth) < 0.02  # as with even light
    assert fit.summary()["light_unevenness_percent"] == pytest.approx(49.0, abs=1.0)


def test_a_prior_from_store_cameras_needs_enough_of_them(tmp_path: Path) -> None:
    store = CalibrationStore.create_default(tmp_path / "store")
    with pytest.raises(RigError, match="holds 3 camera.*--prior"):
        training_set_from_store(store)


def test_a_store_prior_learns_from_measured_cameras_only(
    tmp_path: Path, training: TrainingSet
) -> None:
    store = CalibrationStore.create_default(tmp_path / "store")
    for name in training.names[:3]:
        store.add_camera(name, DEFAULT_GRID.wavelengths, training.sensitivity(name), {})
    estimate = training.sensitivity(training.names[3])
    store.add_camera("from a chart", DEFAULT_GRID.wavelengths, estimate, {"method": "chart-fit"})
    got = training_set_from_store(store, exclude=(training.names[0],))
    assert len(got.names) == 5 and training.names[0] not in got.names
    assert "from a chart" not in got.names
    assert np.allclose(got.sensitivities.max(axis=(1, 2)), 1.0)


def test_the_scale_of_the_photos_does_not_change_the_estimate(
    training: TrainingSet, lamps: np.ndarray, chart: np.ndarray
) -> None:
    prior = build_prior(training.without(HELD_OUT))
    patches = simulate_patches(training.sensitivity(HELD_OUT), lamps[1], chart)
    a = fit_camera(patches, lamps[1], chart, prior)
    b = fit_camera(patches * 1000.0, lamps[1] * 0.01, chart, prior)
    assert np.allclose(a.sensitivity, b.sensitivity, atol=1e-5)
    assert b.exposure[0] == pytest.approx(a.exposure[0] * 1e5, rel=1e-4)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda y: y[:, :23], r"shape \(1, 23, 3\), expected \(photos, 24, 3\)"),
        (
            lambda y: np.where(np.arange(24)[None, :, None] == 4, -0.1, y),
            "patch 5 channel R .* is negative",
        ),
        (
            lambda y: np.where(np.arange(3) == 2, np.nan, y),
            "patch 1 channel B .* missing or saturated",
        ),
        (lambda y: y * 0.0, "photo 1 has no signal"),
    ],
)
def test_bad_patch_values_are_refused_in_one_line(change: object, message: str) -> None:
    y = np.full((1, 24, 3), 0.5)
    with pytest.raises(RigError, match=message) as error:
        validate_patches(change(y))  # type: ignore[operator]
    assert "\n" not in str(error.value)


def test_saturated_patches_are_refused(
    training: TrainingSet, lamps: np.ndarray, chart: np.ndarray
) -> None:
    patches = simulate_patches(training.sensitivity(HELD_OUT), lamps, chart) * 4000
    with pytest.raises(RigError, match="photo 1 patch 19 channel G .* is saturated"):
        fit_camera(patches, lamps, chart, build_prior(training), white_level=3900)


def test_lamps_must_match_the_photos(training: TrainingSet, chart: np.ndarray) -> None:
    with pytest.raises(RigError, match="one lamp SPD per photo"):
        fit_camera(np.full((3, 24, 3), 0.5), np.ones((2, 31)), chart, build_prior(training))


def test_a_camspec_row_of_the_wrong_length_names_its_line(tmp_path: Path) -> None:
    bad = tmp_path / "cams.txt"
    bad.write_text("# comment\nCam A\n" + "1 " * 33 + "\n" + "1 " * 32 + "\n" + "1 " * 33 + "\n")
    with pytest.raises(RigError, match=r"cams.txt:4: 32 values for camera 'Cam A'"):
        read_camspec(bad)
