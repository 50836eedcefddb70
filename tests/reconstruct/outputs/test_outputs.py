"""Export files (PLY, npz, report), relighting, evaluation and the commands reading them."""

from __future__ import annotations

import json
from pathlib import Path

import colour
import numpy as np
import pytest
import trimesh
import yaml

from calibration.grid import SpectralGrid
from core.errors import RigError
from reconstruct.optimise.mesh import vertex_normals
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.steps import OptimiseResult
from reconstruct.optimise.synthetic import SyntheticScene
from reconstruct.outputs import export
from reconstruct.outputs.evaluate import (
    evaluate,
    interpolate_at,
    surface_distance,
    unmeasured_patches,
)
from reconstruct.outputs.gltf import Z_UP_TO_Y_UP
from reconstruct.outputs.relight import Camera, encode_srgb, illuminant_spd, relight
from reconstruct.outputs.result import load_result
from reconstruct.run.pipeline import export_result
from rig.cli import main
from rig.view.colour import linear_srgb_matrix


@pytest.fixture(scope="module")
def recon_dir(tmp_path_factory: pytest.TempPathFactory, scene: SyntheticScene) -> Path:
    """A reconstruction folder written by the exporter from the true scene."""
    out = tmp_path_factory.mktemp("session") / "recon"
    n = len(scene.vertices)
    light = scene.light_offset[None]
    result = OptimiseResult(
        vertices=scene.vertices,
        faces=scene.faces,
        alpha=scene.alpha,
        reflectance=scene.reflectance,
        light=light,
        light_positions=np.stack([p.light_position(scene.light_offset) for p in scene.rig.poses]),
        observed=np.ones(n, bool),
        n_observations=10,
        stage_seconds={"joint": 1.0},
        history=[
            {
                "stage": "joint",
                "outer": 1,
                "iteration": 0,
                "accepted": True,
                "terms": {
                    "total": 2.0,
                    "rendering": 1.0,
                    "spectral": 0.5,
                    "photometric": 0.3,
                    "geometric": 0.2,
                },
            }
        ],
        initial_alpha=scene.alpha,
        colour_source=np.r_[1, np.arange(1, n)],  # vertex 0 carries vertex 1's colour
    )
    export_result(
        out, scene.input(), result, OptimiseSettings(), {"reflectance_scale_absolute": True}
    )
    return out


def test_ply_reads_back_with_trimesh_and_plain_parsing(
    recon_dir: Path, scene: SyntheticScene
) -> None:
    path = recon_dir / export.MESH_FILE
    mesh = trimesh.load(path, process=False)
    assert np.allclose(mesh.vertices, scene.vertices, atol=1e-7)
    assert np.array_equal(mesh.faces, scene.faces)
    raw = mesh.metadata["_ply_raw"]["vertex"]["data"]
    assert np.allclose(raw["refl_550"], scene.reflectance[:, 15], atol=1e-6)
    assert mesh.visual.vertex_colors.shape == (len(scene.vertices), 4)
    text = path.read_bytes().split(b"end_header\n")[0].decode()
    assert "format binary_little_endian 1.0" in text
    assert "property float refl_400" in text and "property float refl_700" in text
    assert "property uchar red" in text


def test_ply_spectra_reach_plyfile(recon_dir: Path, scene: SyntheticScene) -> None:
    plyfile = pytest.importorskip("plyfile")
    vertex = plyfile.PlyData.read(str(recon_dir / export.MESH_FILE))["vertex"]
    assert np.allclose(vertex["refl_700"], scene.reflectance[:, 30], atol=1e-6)
    assert {"red", "refl_400"} <= set(vertex.data.dtype.names)


def test_load_result_gives_mesh_spectra_uncertainty_and_report(
    recon_dir: Path, scene: SyntheticScene
) -> None:
    session = recon_dir.parent
    for path in (recon_dir, session, str(session)):
        assert load_result(path).paths.recon_dir == recon_dir
    result = load_result(session)
    n = len(scene.vertices)
    assert np.allclose(result.mesh.vertices, scene.vertices, atol=1e-7)
    assert np.array_equal(result.mesh.faces, scene.faces)
    # the PLY's properties, which trimesh alone leaves in metadata['_ply_raw']
    attributes = result.mesh.vertex_attributes
    assert np.allclose(attributes["refl_550"], scene.reflectance[:, 15], atol=1e-6)
    assert {"red", "green", "blue", "refl_400", "refl_700"} <= set(attributes)
    assert result.reflectance.shape == (n, 31)
    assert np.allclose(result.reflectance, scene.reflectance)
    spectra = result.spectra
    assert isinstance(spectra, colour.MultiSpectralDistributions)
    assert np.allclose(spectra[550.0], scene.reflectance[:, 15])
    assert spectra.values.shape == (31, n)
    assert result.observed.shape == (n,)
    assert "light" in result.report
    assert result.paths.mesh == recon_dir / export.MESH_FILE


def test_load_result_finds_the_demo_folders_session(
    recon_dir: Path, tmp_path: Path
) -> None:
    demo = tmp_path / "demo-out"
    (demo / "session").mkdir(parents=True)
    (demo / "session" / "session.yaml").write_text("format: 1\n")
    (demo / "session" / "recon").symlink_to(recon_dir)
    assert load_result(demo).paths.recon_dir == demo / "session" / "recon"
    with pytest.raises(RigError, match="holds no reflectance.npz"):
        load_result(tmp_path)


def test_npz_and_report_hold_the_fixed_names(recon_dir: Path, scene: SyntheticScene) -> None:
    data = export.read_reflectance_npz(recon_dir / export.REFLECTANCE_FILE)
    for key in ("vertices", "faces", "wavelengths_nm", "reflectance", "alpha", "basis"):
        assert key in data
    assert data["reflectance"].shape == (len(scene.vertices), 31)
    assert data["colour_source"][:2].tolist() == [1, 1]
    report = json.loads((recon_dir / export.REPORT_FILE).read_text())
    assert report["colour_from_neighbours"] == 1
    assert np.allclose(report["light"]["offset_m"], scene.light_offset)
    assert len(report["light"]["positions_m"]) == scene.rig.n_views
    assert report["reflectance_scale_absolute"] is True
    assert report["history"][0]["terms"]["total"] == 2.0
    for name in ("cameras_lights.png", "cost.png", "spectra.png"):
        assert (recon_dir / name).stat().st_size > 1000


def test_evaluation_of_the_truth_and_of_a_shifted_mesh(
    recon_dir: Path, scene: SyntheticScene, tmp_path: Path
) -> None:
    gt_mesh = tmp_path / "gt.ply"
    trimesh.Trimesh(scene.vertices, scene.faces, process=False).export(gt_mesh)
    gt_refl = tmp_path / "gt.npy"
    np.save(gt_refl, scene.reflectance)
    ev = evaluate(recon_dir, gt_mesh, gt_refl, scene.light_offset + [0.0, 0.003, 0.004])
    assert ev.accuracy_m < 1e-6 and ev.completeness_m < 1e-6
    assert ev.spectral_rmse < 1e-6
    assert ev.light_offset_error_m == pytest.approx(0.005, abs=1e-9)
    assert ev.outside_unit_range == 0
    assert (recon_dir / "spectral_error_map.png").is_file()
    # a reconstruction with impossible values is told so, sample by sample
    bad = tmp_path / "bad.npz"
    arrays = dict(np.load(recon_dir / "reflectance.npz"))
    arrays["reflectance"][:2, :3] = [[-0.1, 0.2, 1.3], [0.5, 1.01, 0.0]]
    np.savez(bad, **arrays)
    ev = evaluate(bad, gt_mesh, gt_refl, None, tmp_path / "bad")
    assert ev.outside_unit_range == 3
    assert ev.reflectance_range == (-0.1, 1.3)
    normals, _ = vertex_normals(scene.vertices, scene.faces)
    d, _, _ = surface_distance(
        scene.vertices + 0.001 * normals, trimesh.load(gt_mesh, process=False)
    )
    assert np.mean(d) == pytest.approx(0.001, rel=0.05)


def test_relight_white_is_neutral_under_d65_and_warm_under_a(scene: SyntheticScene) -> None:
    pose = scene.rig.poses[0]
    from reconstruct.model.camera import Intrinsics

    cam = Camera(Intrinsics.pinhole(60, 45, 90.0), pose)
    white = np.ones_like(scene.reflectance)
    d65 = relight(
        scene.vertices, scene.faces, white, scene.basis.wavelengths_nm, cam, pose.center, "D65"
    )
    a = relight(
        scene.vertices, scene.faces, white, scene.basis.wavelengths_nm, cam, pose.center, "A"
    )
    centre = d65[20:25, 28:32].reshape(-1, 3).mean(axis=0)
    assert np.allclose(centre / centre.max(), 1.0, atol=0.02)
    warm = a[20:25, 28:32].reshape(-1, 3).mean(axis=0)
    assert warm[0] > 1.5 * warm[2]
    assert encode_srgb(d65).dtype == np.uint8


def test_commands_relight_and_evaluate(
    recon_dir: Path, scene: SyntheticScene, tmp_path: Path
) -> None:
    camera = tmp_path / "cam.yaml"
    camera.write_text(
        yaml.safe_dump(
            {
                "width": 64,
                "height": 48,
                "focal_px": 100.0,
                "eye": [0.3, 0.0, 0.1],
                "target": [0, 0, 0],
            }
        )
    )
    out = tmp_path / "relit.png"
    session = recon_dir.parent
    assert (
        main(
            [
                "relight",
                str(session),
                "--camera",
                str(camera),
                "--illuminant",
                "A",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert out.stat().st_size > 200
    gt_mesh = tmp_path / "gt.ply"
    trimesh.Trimesh(scene.vertices, scene.faces, process=False).export(gt_mesh)
    np.save(tmp_path / "gt.npy", scene.reflectance)
    assert (
        main(
            [
                "evaluate",
                str(session),
                "--gt-mesh",
                str(gt_mesh),
                "--gt-reflectance",
                str(tmp_path / "gt.npy"),
                "--gt-light-offset",
                "0.06,-0.02,0",
            ]
        )
        == 0
    )
    assert main(["relight", str(session), "--camera", str(camera), "--light-pos", "1,2"]) == 2
    assert main(["reconstruct", str(tmp_path / "nowhere")]) == 2


def test_unknown_settings_name_the_key() -> None:
    with pytest.raises(RigError, match="gama"):
        OptimiseSettings.from_mapping({"gama": [1, 2, 3]})
    with pytest.raises(RigError, match="robust"):
        OptimiseSettings.from_mapping({"robust": "tukey"})
    s = OptimiseSettings.from_mapping({"gamma": [0.1, 1, 0.1], "solver": {"max_iterations": 3}})
    assert s.gamma == (0.1, 1.0, 0.1) and s.solver.max_iterations == 3


def test_demo_profile_is_a_valid_sim_profile() -> None:
    from rig.demo_profile import demo_profile
    from rig.profile import parse_profile

    profile = parse_profile(demo_profile(12), "demo profile")
    assert profile.plan.views == 12
    assert sorted(profile.illuminations) == ["LED1", "LED2"]
    assert main(["demo", "--views", "3"]) == 2


def test_config_errors_name_the_file_and_section(tmp_path: Path) -> None:
    from reconstruct.run.pipeline import _scaled, load_config

    bad = tmp_path / "recon.yaml"
    bad.write_text("optimize: {gamma: [1, 2, 3]}\n")
    with pytest.raises(RigError, match="optimize"):
        load_config(bad)
    good = tmp_path / "ok.yaml"
    good.write_text("subdivide: {max_faces: 1000}\noptimise: {robust: huber}\n")
    assert load_config(good)["optimise"]["robust"] == "huber"
    from reconstruct.model.camera import Intrinsics

    half = _scaled(Intrinsics.pinhole(640, 480, 800.0), 320, 240)
    assert half.params == (400.0, 400.0, 160.0, 120.0)
    with pytest.raises(RigError, match="decoded frames"):
        _scaled(Intrinsics.pinhole(640, 480, 800.0), 320, 200)


def test_the_documented_reconstruct_config_loads(tmp_path: Path) -> None:
    from reconstruct.run.pipeline import load_config

    doc = (Path(__file__).parents[3] / "docs" / "usage-reconstruct.md").read_text()
    example = doc.split("`--config` takes a YAML file")[1].split("```yaml\n")[1].split("```")[0]
    path = tmp_path / "documented.yaml"
    path.write_text(example)
    assert set(load_config(path)) == {"subdivide", "optimise"}


def test_evaluate_reports_ciede2000_per_vertex_and_per_patch(
    recon_dir: Path, scene: SyntheticScene, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    gt_mesh = tmp_path / "gt.ply"
    trimesh.Trimesh(scene.vertices, scene.faces, process=False).export(gt_mesh)
    truth = tmp_path / "reflectance.npy"
    np.save(truth, scene.reflectance)
    # without patch.npy: ΔE00 per vertex only, zero for the truth itself
    ev = evaluate(recon_dir, gt_mesh, truth)
    assert [c["illuminant"] for c in ev.colour] == ["D65", "A"]
    assert all(c["per_vertex"]["p90"] < 1e-6 and not c["patches"] for c in ev.colour)
    # a brighter truth on two patches, labelled in patch.npy beside the reflectance
    patch = np.where(scene.vertices[:, 2] < np.median(scene.vertices[:, 2]), 0, 1)  # two caps
    patch[:3] = -1
    np.save(tmp_path / "patch.npy", patch)
    np.save(truth, scene.reflectance * 1.1)
    csv = tmp_path / "lamp.csv"
    samples = "".join(f"{w},{w / 100}\n" for w in range(390, 711, 20))
    csv.write_text("wavelength_nm,power\n" + samples)
    code = main(["evaluate", str(recon_dir.parent), "--gt-mesh", str(gt_mesh),
                 "--gt-reflectance", str(truth), "--illuminant", "FL2",
                 "--illuminant", str(csv)])  # fmt: skip
    assert code == 0
    printed = capsys.readouterr().out
    assert "ΔE00 D65 per vertex" in printed and "ΔE00 FL2 per patch" in printed
    assert "ΔE00 lamp" in printed and "per patch (2 of 2 measured)" in printed
    saved = json.loads((recon_dir / "evaluation.json").read_text())
    colour = {c["illuminant"]: c for c in saved["colour"]}
    assert list(colour) == ["D65", "A", "FL2", "lamp"]
    for c in colour.values():
        assert 0.5 < c["per_vertex"]["mean"] < 10
        assert [p["name"] for p in c["patches"]] == ["dark skin", "light skin"]
        assert c["patch_max"] >= c["patch_mean"] > 0.5 and c["patches_measured"] == 2


def test_a_patch_seen_along_its_border_only_is_not_measured() -> None:
    # a 10 mm square of 0.5 mm edges: patch 0, with a strip two vertices wide of patch 1
    # whose interior (the outer column) is 21 vertices, less than a 3 mm aperture's 7.1 mm²
    xs, ys = np.meshgrid(np.arange(21) * 5e-4, np.arange(21) * 5e-4)
    vertices = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    k = np.arange(20 * 20)
    i, j = k // 20, k % 20
    a, b, c, d = i * 21 + j, i * 21 + j + 1, (i + 1) * 21 + j, (i + 1) * 21 + j + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    patch = np.where(xs.ravel() < 7e-4, 1, 0)
    observed = np.ones(len(vertices), bool)
    assert unmeasured_patches(vertices, faces, patch, observed) == [1]
    wider = np.where(xs.ravel() < 1.2e-3, 1, 0)  # three columns: two inside, 10 mm² and more
    assert unmeasured_patches(vertices, faces, wider, observed) == []
    # unobserved vertices are no interior: patch 0 seen only on a 2-column strip
    assert unmeasured_patches(vertices, faces, wider, xs.ravel() < 2.7e-3) == [0]


def test_evaluate_a_sim_truth_names_its_colorchecker_patches(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from drivers.sim.rig import SimRig

    gt = tmp_path / "session" / "ground_truth"
    SimRig({"views": 4, "subdivisions": 3}, seed=0).write_ground_truth(gt)
    mesh = trimesh.load(gt / "mesh.ply", process=False)
    truth = np.load(gt / "reflectance.npy")
    n = len(mesh.vertices)
    estimate = truth.copy()
    estimate[np.load(gt / "patch.npy") == 0] *= 1.25  # "dark skin" read too bright
    recon = tmp_path / "session" / "recon"
    recon.mkdir()
    wl = np.arange(400.0, 701.0, 10.0)
    export.write_reflectance_npz(
        recon / export.REFLECTANCE_FILE, np.asarray(mesh.vertices), np.asarray(mesh.faces),
        np.asarray(mesh.vertex_normals), wl, estimate, np.zeros((n, 8)), np.zeros((31, 8)),
        np.ones(n, bool),
    )  # fmt: skip
    args = ["evaluate", str(tmp_path / "session"), "--gt-mesh", str(gt / "mesh.ply"),
            "--gt-reflectance", str(gt / "reflectance.npy")]  # fmt: skip
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "dark skin" in printed and "ΔE00 A per patch (24 of 24 measured)" in printed
    colour = json.loads((recon / "evaluation.json").read_text())["colour"]
    d65 = {p["name"]: p["delta_e00"] for p in colour[0]["patches"]}
    assert d65["dark skin"] > 1.0 and colour[0]["patch_max"] == d65["dark skin"]
    assert max(v for k, v in d65.items() if k != "dark skin") < 1e-6


def test_export_glb_reads_back_with_linear_colours_and_spectra(
    recon_dir: Path, scene: SyntheticScene, tmp_path: Path
) -> None:
    glb = tmp_path / "model.glb"
    assert main(["export", str(recon_dir.parent), "--glb", str(glb), "--illuminant", "A"]) == 0
    loaded = trimesh.load(glb, process=False)  # trimesh's glTF reader
    (mesh,) = loaded.geometry.values()
    # z up -> glTF's y up
    assert np.allclose(mesh.vertices, scene.vertices @ Z_UP_TO_Y_UP.T, atol=1e-6)
    assert np.array_equal(mesh.faces, scene.faces)
    for k, w in enumerate(range(400, 701, 10)):
        values = np.ravel(mesh.vertex_attributes[f"_REFLECTANCE_{w}"])  # a SCALAR accessor
        assert np.allclose(values, scene.reflectance[:, k], atol=1e-6)
    # COLOR_0 is linear: the viewer's matrix under A, before the sRGB transfer function
    grid = SpectralGrid.from_wavelengths(np.arange(400.0, 701.0, 10.0))
    linear = np.clip(scene.reflectance @ linear_srgb_matrix(grid, illuminant_spd("A", grid)), 0, 1)
    colours = mesh.visual.vertex_colors[:, :3] / 255.0
    assert np.abs(colours - linear).max() <= 0.5 / 255 + 1e-9
    assert not np.allclose(colours, encode_srgb(linear), atol=0.02)  # not sRGB-encoded
    assert mesh.metadata["illuminant"] == "A"


def test_export_refuses_a_name_without_glb(recon_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(SystemExit):
        main(["export", str(recon_dir)])
    assert main(["export", str(recon_dir), "--glb", str(tmp_path / "model.gltf")]) == 2


def test_commands_accept_the_demo_folder(recon_dir: Path, tmp_path: Path) -> None:
    demo = tmp_path / "demo-out"  # `rig demo --out demo-out` puts its session in session/
    (demo / "session").mkdir(parents=True)
    (demo / "session" / "session.yaml").write_text("format: 1\n")
    (demo / "session" / "recon").symlink_to(recon_dir)
    camera = tmp_path / "cam.yaml"
    camera.write_text(yaml.safe_dump(
        {"width": 32, "height": 24, "focal_px": 50.0, "eye": [0.3, 0.0, 0.1], "target": [0, 0, 0]}
    ))
    assert main(["view", str(demo), "--export", str(tmp_path / "v.html")]) == 0
    assert main(["export", str(demo), "--glb", str(tmp_path / "m.glb")]) == 0
    relit = tmp_path / "relit.png"
    assert main(["relight", str(demo), "--camera", str(camera), "--out", str(relit)]) == 0
    assert relit.is_file()


def test_values_on_a_zero_area_triangle_are_its_nearest_corners() -> None:
    """Scanned meshes carry a few degenerate faces: the truth looked up there is still a
    number (it was NaN, and made a whole scene's mean NaN)."""

    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [3, 0, 0], [4, 0, 0]])
    faces = np.array([[0, 1, 2], [3, 4, 5]])  # the second is a line: zero area
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    values = np.arange(6.0)[:, None] * np.ones((1, 2))
    points = np.array([[0.25, 0.25, 0.0], [3.9, 0.0, 0.0]])
    out = interpolate_at(mesh, values, points, np.array([0, 1]))
    np.testing.assert_allclose(out[0], [0.75, 0.75])  # 0.5·0 + 0.25·1 + 0.25·2
    np.testing.assert_allclose(out[1], [5.0, 5.0])
