"""CIEDE2000 between reflectance spectra: known values, the Lab white, per-vertex summaries and
per-patch aggregation, illuminants by name, file and array, and the information floor."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calibration.basis import default_basis
from calibration.colorimetry import reflectance_to_srgb, reflectance_to_xyz, xyz_weights
from calibration.colour_difference import (
    colour_report,
    delta_e00,
    delta_e00_lab,
    illuminant,
    per_patch,
    reflectance_to_lab,
    summarise,
)
from calibration.defaults import (
    camera_sensitivity,
    cie_illuminant,
    colorchecker_reflectances,
)
from calibration.estimation import noise_free_estimate, response_matrices
from core.errors import RigError

# Sharma, Wu & Dalal (2005), "The CIEDE2000 color-difference formula": test pairs 1, 7, 17, 25
SHARMA = [
    ((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
    ((50.0, 0.0, 0.0), (50.0, -1.0, 2.0), 2.3669),
    ((50.0, 2.5, 0.0), (73.0, 25.0, -18.0), 27.1492),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
]


@pytest.mark.parametrize(("lab_a", "lab_b", "expected"), SHARMA)
def test_published_ciede2000_pairs(lab_a: tuple, lab_b: tuple, expected: float) -> None:
    assert float(delta_e00_lab(np.array(lab_a), np.array(lab_b))) == pytest.approx(
        expected, abs=1e-4
    )


@pytest.mark.parametrize("name", ["D65", "A"])
def test_perfect_diffuser_is_the_lab_white(name: str) -> None:
    lab = reflectance_to_lab(np.ones(31), illuminant(name))
    assert lab == pytest.approx([100.0, 0.0, 0.0], abs=1e-6)
    grey = reflectance_to_lab(np.full(31, 0.18), illuminant(name))
    assert grey[0] == pytest.approx(49.5, abs=0.1) and np.hypot(*grey[1:]) < 1e-6


def test_identical_spectra_have_no_difference_and_changes_do() -> None:
    _, cc = colorchecker_reflectances()
    light = illuminant("D65")
    assert np.all(delta_e00(cc, cc, light) == 0.0)
    de = delta_e00(cc, cc * 1.1, light)
    assert np.all(de > 0.5) and np.all(de < 10)
    # the same pair differs by a different amount under tungsten light
    assert not np.allclose(de, delta_e00(cc, cc * 1.1, illuminant("A")))


def test_srgb_and_delta_e_share_one_xyz_path() -> None:
    _, cc = colorchecker_reflectances()
    w = xyz_weights(illuminant="A")
    assert np.allclose(reflectance_to_xyz(cc, illuminant="A"), cc @ w)
    assert reflectance_to_srgb(np.ones(31)) == pytest.approx([1.0, 1.0, 1.0], abs=2e-3)


def test_illuminant_from_array_file_and_bad_input(tmp_path: Path) -> None:
    spd = cie_illuminant("A")
    assert np.allclose(illuminant(spd * 7.0, name="A7").spd, spd * 7.0)
    csv = tmp_path / "lamp.csv"
    wl = np.arange(380, 781, 5.0)
    csv.write_text("wavelength_nm,power\n" + "".join(f"{w},{1 + w / 1000}\n" for w in wl))
    lamp = illuminant(str(csv))
    assert lamp.name == "lamp" and lamp.spd.shape == (31,)
    _, cc = colorchecker_reflectances()
    # white is the illuminant's own diffuser, so the scale of the SPD never matters
    assert np.allclose(delta_e00(cc, cc * 0.9, illuminant(spd)),
                       delta_e00(cc, cc * 0.9, illuminant(spd * 7.0)))  # fmt: skip
    with pytest.raises(RigError, match="illuminant"):
        illuminant("D99")
    with pytest.raises(RigError, match="does not exist"):
        illuminant(str(tmp_path / "missing.csv"))
    with pytest.raises(RigError, match="no power"):
        illuminant(np.zeros(31))


def test_summaries_use_only_the_masked_finite_values() -> None:
    s = summarise(np.array([1.0, 2.0, 3.0, 100.0, np.nan]), np.array([1, 1, 1, 0, 1], bool))
    assert (s.mean, s.median) == (2.0, 2.0) and s.p90 == pytest.approx(2.8)
    assert np.isnan(summarise(np.array([np.nan])).mean)


def test_per_patch_takes_the_median_spectrum_of_each_patch() -> None:
    names, cc = colorchecker_reflectances()
    light = illuminant("D65")
    patch = np.array([3, 3, 3, 3, 5, 5, 5, -1])
    truth = cc[np.maximum(patch, 0)]
    estimate = truth.copy()
    estimate[0] = 1.0  # one stray vertex on patch 3: the median ignores it
    estimate[4:7] *= 1.2  # patch 5 is uniformly too bright
    rows = per_patch(estimate, truth, patch, light, names=names)
    assert [(r.patch, r.name, r.vertices) for r in rows] == [(3, names[3], 4), (5, names[5], 3)]
    assert rows[0].delta_e00 == pytest.approx(0.0, abs=1e-9)
    expected = float(delta_e00(cc[5] * 1.2, cc[5], light))
    assert rows[1].delta_e00 == pytest.approx(expected) and rows[1].rmse > 0
    observed = np.array([0, 1, 1, 1, 1, 1, 1, 1], bool)
    report = colour_report(estimate, truth, light, observed, patch, names)
    assert report.patch_mean == pytest.approx(expected / 2) and report.patch_max == expected
    assert report.per_vertex.mean == pytest.approx(np.mean(delta_e00(estimate, truth, light)[1:]))
    d = report.as_dict()
    assert d["illuminant"] == "D65" and len(d["patches"]) == 2
    assert colour_report(estimate, truth, light).as_dict()["patch_mean"] is None


def test_an_unmeasured_patch_is_listed_but_left_out_of_the_mean_and_max() -> None:
    names, cc = colorchecker_reflectances()
    light = illuminant("D65")
    patch = np.array([3, 3, 5, 5, 9])
    truth = cc[patch]
    estimate = truth * np.array([1.1, 1.1, 1.0, 1.0, 2.0])[:, None]
    report = colour_report(estimate, truth, light, None, patch, names, unmeasured=[9])
    assert [(r.patch, r.measured) for r in report.patches] == [(3, True), (5, True), (9, False)]
    expected = float(delta_e00(cc[3] * 1.1, cc[3], light))
    assert report.patch_mean == pytest.approx(expected / 2)
    assert report.patch_max == pytest.approx(expected)
    assert report.patches[2].delta_e00 > 2 * expected  # the unmeasured patch's error
    d = report.as_dict()
    assert d["patches_measured"] == 2 and d["patches"][2]["measured"] is False
    none = colour_report(estimate, truth, light, None, patch, names, unmeasured=[3, 5, 9])
    assert none.as_dict()["patch_mean"] is None and len(none.patches) == 3


def test_information_floor_shrinks_with_more_illuminations() -> None:
    _, cc = colorchecker_reflectances()
    basis = default_basis()
    camera = camera_sensitivity()
    light = illuminant("D65")

    def floor(names: list[str]) -> float:
        resp = response_matrices(camera, [cie_illuminant(n) for n in names])
        return float(np.mean(delta_e00(noise_free_estimate(cc, resp, basis), cc, light)))

    one, three = floor(["D65"]), floor(["A", "D65", "FL11"])
    assert 0 < three < one


def test_docstring_examples() -> None:
    import doctest

    import calibration.colour_difference as module

    assert doctest.testmod(module).failed == 0
