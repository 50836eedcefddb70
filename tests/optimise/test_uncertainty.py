"""Per-vertex uncertainty from the final linearisation, and where it is exported."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import spearmanr

from reconstruct import export
from reconstruct.optimise.cost import JointCost
from reconstruct.optimise.steps import OptimiseSettings, build_problem, optimise
from reconstruct.optimise.synthetic import SyntheticScene, make_scene
from reconstruct.optimise.uncertainty import VertexUncertainty, vertex_uncertainty
from reconstruct.pipeline import export_result


def _at_truth(scene: SyntheticScene) -> VertexUncertainty:
    light = scene.light_offset[None]
    problem = build_problem(scene.input(), scene.vertices, light, OptimiseSettings())
    theta = problem.pack(scene.vertices, scene.alpha, light)
    return vertex_uncertainty(JointCost(problem), theta, problem.obs.per_vertex > 0)


@pytest.fixture(scope="module")
def noisy() -> tuple[SyntheticScene, SyntheticScene]:
    return make_scene(3, 8, noise=0.002, seed=4), make_scene(3, 8, noise=0.004, seed=4)


def test_noise_level_is_read_from_the_residuals_and_scales_the_std(noisy):
    a, b = (_at_truth(s) for s in noisy)
    # at the truth the residuals are the noise (the basis reproduces the reflectance), summed
    # over 3M residuals but divided by the 3M − n_params degrees of freedom of a fit
    light = noisy[0].light_offset[None]
    problem = build_problem(noisy[0].input(), noisy[0].vertices, light, OptimiseSettings())
    m3 = 3 * problem.obs.count
    inflation = np.sqrt(m3 / a.dof)
    assert a.noise_std == pytest.approx(0.002 * inflation, rel=0.1)
    assert b.noise_std == pytest.approx(0.004 * inflation, rel=0.1)
    ok = np.isfinite(a.reflectance_std[:, 0])
    ratio = b.reflectance_std[ok] / a.reflectance_std[ok]
    # twice the noise: at least twice the std (noisier colours also loosen the photometric
    # smoothness weights, so a little more)
    assert np.median(ratio) >= 0.95 * b.noise_std / a.noise_std


def test_unobserved_vertices_have_no_uncertainty_and_more_views_mean_less(noisy):
    scene = noisy[0]
    unc = _at_truth(scene)
    light = scene.light_offset[None]
    problem = build_problem(scene.input(), scene.vertices, light, OptimiseSettings())
    count = problem.obs.per_vertex
    assert unc.reflectance_std.shape == scene.reflectance.shape
    assert unc.position_std_m.shape == (len(scene.vertices),)
    assert np.all(np.isnan(unc.reflectance_std[count == 0]))
    seen = count > 0
    assert np.all(np.isfinite(unc.reflectance_std[seen]))
    assert np.all(unc.position_std_m[seen] > 0)
    rho = spearmanr(count[seen], unc.reflectance_std[seen].mean(axis=1)).statistic
    assert rho < -0.3


def test_optimise_reports_and_export_writes_the_uncertainty(tmp_path, noisy):
    scene = noisy[0]
    inp = scene.input()
    cfg = OptimiseSettings(outer_iterations=1, joint_iterations=3, light_iterations=5)
    result = optimise(inp, cfg)
    unc = result.uncertainty
    assert unc is not None
    assert np.all(np.isfinite(unc.reflectance_std[result.observed]))
    figures, report, mesh, npz, report_path = export_result(
        tmp_path, inp, result, cfg, {"reflectance_scale_absolute": True}
    )
    data = export.read_reflectance_npz(npz)
    np.testing.assert_array_equal(data["reflectance_std"], unc.reflectance_std)
    np.testing.assert_array_equal(data["position_std_m"], unc.position_std_m)
    header = mesh.read_bytes().split(b"end_header")[0].decode()
    assert "property float refl_std_400" in header and "property float position_std_m" in header
    summary = json.loads(report_path.read_text())["uncertainty"]
    assert summary["vertices_with_uncertainty"] == int(result.observed.sum())
    assert summary["reflectance_std_median"] > 0
    assert tmp_path / "uncertainty.png" in figures
