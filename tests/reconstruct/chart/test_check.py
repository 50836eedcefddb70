"""The chart check's pieces: the shading plane fitted through the calibration, and reference
files of any target."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calibration.basis import default_basis
from calibration.defaults import camera_sensitivity, cie_illuminant, colorchecker_reflectances
from calibration.estimation import estimate_reflectance, response_matrices
from calibration.grid import DEFAULT_GRID
from core.errors import RigError
from reconstruct.chart.check import chart_coordinates, estimate_view, fit_shading
from reconstruct.chart.detect import layout
from reconstruct.chart.patches import ChartPatches
from reconstruct.chart.reference import default_reference, read_reference

CHART = layout("classic24")


@pytest.fixture(scope="module")
def setup() -> tuple[np.ndarray, np.ndarray]:
    responses = response_matrices(
        camera_sensitivity(), [cie_illuminant("A"), cie_illuminant("D65")]
    )
    return responses, colorchecker_reflectances()[1]


def _shaded(responses: np.ndarray, refl: np.ndarray, plane: np.ndarray) -> np.ndarray:
    shading = np.column_stack([np.ones(24), chart_coordinates(CHART)]) @ plane
    return shading[:, None, None] * np.einsum("kcl,pl->pkc", responses, refl)


def test_the_plane_is_recovered_and_one_wrong_patch_barely_moves_it(setup) -> None:
    responses, refl = setup
    plane = np.array([2.0, 0.3, -0.2])
    y = _shaded(responses, refl, plane)
    predicted = np.einsum("kcl,pl->pkc", responses, refl)
    np.testing.assert_allclose(fit_shading(y, predicted, CHART), plane, rtol=1e-6)
    y[7] *= [1.3, 0.8, 1.0]  # one patch's colour wrong by 20–30 %
    np.testing.assert_allclose(fit_shading(y, predicted, CHART), plane, rtol=0.02)


def test_a_plane_shaded_chart_estimates_as_if_unshaded(setup) -> None:
    responses, refl = setup
    basis = default_basis()
    y = _shaded(responses, refl, np.array([0.7, -0.15, 0.1]))
    patches = {
        name: ChartPatches(y[:, k], np.zeros((24, 3)), np.zeros((4, 2)), np.zeros((24, 4, 2)),
                           np.ones(24, int))
        for k, name in enumerate(("A", "D65"))
    }  # fmt: skip
    estimate, _ = estimate_view(patches, responses, basis, refl, CHART)
    unshaded = estimate_reflectance(_shaded(responses, refl, np.array([1.0, 0, 0])),
                                    responses, basis)[1]  # fmt: skip
    np.testing.assert_allclose(estimate, unshaded, atol=1e-6)


def test_a_reference_csv_is_read_in_its_column_order(tmp_path: Path) -> None:
    wl = np.arange(380.0, 781.0, 5.0)
    values = np.linspace(0.05, 0.9, 24)[None, :] * np.ones((len(wl), 1))
    path = tmp_path / "target.csv"
    header = "wavelength_nm," + ",".join(f"p{k}" for k in range(24))
    np.savetxt(path, np.column_stack([wl, values]), delimiter=",", header=header, comments="")
    ref = read_reference(path, CHART)
    assert ref.names[0] == "p0" and ref.reflectance.shape == (24, DEFAULT_GRID.size)
    np.testing.assert_allclose(ref.reflectance[:, 10], values[0], rtol=1e-6)


def test_a_reference_with_the_wrong_patch_count_or_percent_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "short.csv"
    path.write_text("wavelength_nm,a,b\n400,0.1,0.2\n700,0.1,0.2\n")
    with pytest.raises(RigError, match="short.csv has 2 patch columns"):
        read_reference(path, CHART)
    percent = tmp_path / "percent.csv"
    cols = ",".join(["40"] * 24)
    percent.write_text("wavelength_nm," + ",".join("p" * 24) + f"\n400,{cols}\n700,{cols}\n")
    with pytest.raises(RigError, match="percent"):
        read_reference(percent, CHART)


def test_the_default_reference_is_the_colorchecker() -> None:
    ref = default_reference(CHART)
    assert ref.names[0] == "dark skin" and ref.names[18].startswith("white")


def test_patches_are_read_inside_their_quads_and_saturated_pixels_are_left_out() -> None:
    from reconstruct.chart.detect import ChartGeometry
    from reconstruct.chart.patches import read_values

    image = np.zeros((200, 300, 3), np.float32)
    quads = np.zeros((24, 4, 2))
    for k in range(24):
        r, c = divmod(k, 6)
        x0, y0 = 10 + 45 * c, 10 + 45 * r
        image[y0 : y0 + 40, x0 : x0 + 40] = [k, 2 * k, 3 * k]
        quads[k] = [[x0, y0], [x0 + 40, y0], [x0 + 40, y0 + 40], [x0, y0 + 40]]
    saturated = np.zeros(image.shape[:2], bool)
    saturated[55:95, 55:95] = True  # all of patch 8 (row 1, column 1)
    patches = read_values(image, ChartGeometry(quads, quads[[0, 5, 23, 18], [0, 1, 2, 3]], 0.0),
                          saturated)  # fmt: skip
    assert np.all(np.isnan(patches.rgb[7])) and patches.pixels[7] == 0
    keep = np.arange(24) != 7
    np.testing.assert_array_equal(patches.rgb[keep], np.arange(24)[keep, None] * [1, 2, 3])
    assert np.all(patches.spread[keep] == 0)
    assert np.all((patches.pixels[keep] >= 400) & (patches.pixels[keep] <= 441))  # 20–21 px square
