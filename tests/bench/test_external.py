"""The external-renderer scenes: Mitsuba's shading images against the analytic shading of a
flat plate, linearity of the indicator composition, and a tiny session whose DNGs the decode
stage reads back as the composed image."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import minimum_filter
from tiny_scene import TINY

pytest.importorskip("mitsuba")

from bench._common import brightness, information_floor
from bench.external import reflectance_brightness
from bench.external_render import ShadingRenderer, compose
from bench.external_session import ExternalCamera, Size, build_session
from bench.paper_sim import _write_npz
from reconstruct.frames import decode
from reconstruct.frames.decode import decode_raw
from reconstruct.model.camera import Intrinsics, Pose, project


def plate(n: int = 41, half: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A flat square in z = 0 facing +z: patch 0 where x < 0, patch 1 where x >= 0."""
    g = np.linspace(-half, half, n)
    x, y = np.meshgrid(g, g)
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n, i.ravel() + n + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return vertices, faces, (vertices[:, 0] >= 0).astype(np.int64)


def plate_truth(folder: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Path]:
    """The plate painted blue sky | orange as a truth folder (mesh.ply, reflectance.npy,
    patch.npy) under ``folder``: its vertices, faces, patch labels, reflectance and the folder."""
    import trimesh

    from calibration.defaults import colorchecker_reflectances

    vertices, faces, patch = plate()
    truth = folder / "truth"
    truth.mkdir()
    trimesh.Trimesh(vertices, faces, process=False).export(truth / "mesh.ply")
    reflectance = colorchecker_reflectances()[1][[2, 7]][patch]
    np.save(truth / "reflectance.npy", reflectance)
    np.save(truth / "patch.npy", patch)
    return vertices, faces, patch, reflectance, truth


@pytest.fixture(scope="module")
def plate_render() -> tuple[ShadingRenderer, Pose, np.ndarray]:
    vertices, faces, patch = plate()
    intr = Intrinsics.pinhole(64, 48, 60.0)
    pose = Pose.look_at(np.array([0.03, -0.02, 0.3]), np.zeros(3), up=(0.0, 1.0, 0.0))
    return ShadingRenderer(vertices, faces, patch, intr, spp=16), pose, patch


def test_plate_matches_analytic_shading(
    plate_render: tuple[ShadingRenderer, Pose, np.ndarray],
) -> None:
    renderer, pose, _ = plate_render
    light = pose.light_position(np.array([0.05, 0.0, 0.0]))
    shading = renderer.render(pose, light)
    intr = renderer.intrinsics
    v, u = np.mgrid[0 : intr.height, 0 : intr.width] + 0.5
    rays = pose.R.T @ intr.pixel_rays(np.stack([u.ravel(), v.ravel()], 1)).T  # world dirs
    c = pose.center
    t = -c[2] / rays[2]
    points = c + (rays * t).T
    d = light - points
    dist = np.linalg.norm(d, axis=1)
    analytic = (d[:, 2] / dist / dist**2).reshape(intr.height, intr.width)
    x = points[:, 0].reshape(intr.height, intr.width)
    y = points[:, 1].reshape(intr.height, intr.width)
    inside = (np.abs(x) < 0.09) & (np.abs(y) < 0.09)
    left, right = inside & (x < -0.01), inside & (x > 0.01)  # away from the patch boundary
    assert left.sum() > 100 and right.sum() > 100
    np.testing.assert_allclose(shading[0][left], analytic[left], rtol=0.01)
    np.testing.assert_allclose(shading[1][right], analytic[right], rtol=0.01)
    assert np.all(shading[0][right] == 0) and np.all(shading[1][left] == 0)
    # the world point Mitsuba shows at a pixel is where our camera model projects it
    uv = project(intr, pose, np.array([[-0.05, 0.0, 0.0], [0.05, 0.0, 0.0]]))
    iu, iv = uv.astype(int).T
    assert shading[0][iv[0], iu[0]] > 0 and shading[1][iv[1], iu[1]] > 0


def test_indicator_renders_sum_to_the_white_render(
    plate_render: tuple[ShadingRenderer, Pose, np.ndarray],
) -> None:
    renderer, pose, _ = plate_render
    for light in (pose.light_position(np.array([0.05, 0.0, 0.0])), None):
        shading = renderer.render(pose, light)
        white = renderer.render_white(pose, light)
        assert white.max() > 0
        # the shading comes back as float16 keeps it (the cache's precision, 2^-11 relative)
        np.testing.assert_allclose(shading.sum(axis=0), white, rtol=1e-3, atol=1e-6)
    rgb = np.array([[1.0, 0.0, 0.5], [0.0, 2.0, 0.5]])
    composed = compose(shading, rgb)
    np.testing.assert_allclose(composed[..., 2], 0.5 * white, rtol=1e-3, atol=1e-6)


def test_curved_object_matches_the_project_renderer() -> None:
    """Radiometry, pixel by pixel: Mitsuba's image of a lit sphere is the project's own
    render (cos term, inverse square, smooth normals, pixel footprint) at several distances
    and light angles, so no brightness bias enters between the renderer and the model."""
    import trimesh

    from reconstruct.model import render
    from reconstruct.model.raycast import RayCaster

    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.05)
    vertices, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces, dtype=np.int64)
    intr = Intrinsics.pinhole(64, 48, 80.0)
    renderer = ShadingRenderer(vertices, faces, np.zeros(len(vertices), np.int64), intr, spp=256)
    caster, normals = RayCaster(vertices, faces), render.vertex_normals(vertices, faces)
    white = np.ones((len(vertices), 3))
    for distance, light_offset in ((0.25, (0.1, 0.0, 0.0)), (0.5, (-0.05, 0.2, 0.0))):
        pose = Pose.look_at(np.array([0.0, -distance, 0.05]), np.zeros(3))
        light = pose.light_position(np.array(light_offset))
        mitsuba_image = renderer.render_white(pose, light)
        hits = render.trace_view(caster, intr, pose, 4, "smooth", normals)
        weight = render.light_weight(caster, hits, light)
        ours = render.shade_vertex_rgb(hits, [(weight, white)])[..., 0]
        # whole pixels on the sphere, away from the silhouette and the shadow terminator
        inside = (hits.coverage() > 0.999) & (ours > 0.2 * ours.max())
        assert inside.sum() > 100
        ratio = mitsuba_image[inside] / ours[inside]
        assert abs(np.median(ratio) - 1.0) < 0.003
        assert np.percentile(ratio, 5) > 0.98 and np.percentile(ratio, 95) < 1.02


def test_tiny_session_decodes_to_the_composed_image(
    shared_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from reconstruct.outputs.evaluate import load_mesh

    spec = TINY
    size = Size(width=64, height=48, focal_px=112.0, views=4, spp=16, ambient=0.05)
    composed: dict[tuple[int, str | None], np.ndarray] = {}
    render_linear = ExternalCamera.render_linear

    def recording(camera: ExternalCamera) -> np.ndarray:
        image = render_linear(camera)
        composed[(camera.rig.view, camera.light.illumination)] = image
        return image

    monkeypatch.setattr(ExternalCamera, "render_linear", recording)
    session = build_session(spec, size, tmp_path, shared_data, tmp_path / "cache")
    raws = sorted((session / "raw").glob("*.dng"))
    assert len(raws) == 4 * 3  # ambient + two lamps per view
    assert (session / "poses" / "images.txt").is_file()
    assert (session / "ground_truth" / "reflectance.npy").is_file()
    lit, _ = decode_raw(next(p for p in raws if p.name.endswith("_L1.dng")), "linear", 0.98)
    amb, _ = decode_raw(next(p for p in raws if p.name.endswith("_ambient.dng")), "linear", 0.98)
    assert lit.shape == (48, 64, 3)
    assert lit.mean() > 5 * amb.mean() > 0  # the bulb dominates, the ambient is there
    decoded = decode.run({}, session, tmp_path / "decoded")  # rig reconstruct's decode stage
    assert len(sorted(Path(decoded).glob("frame_*_sat.npy"))) == 12
    # radiometry through the DNG, black/white levels, exposure and demosaic: the decoded frame
    # is the composed linear image (shot and read noise aside), in every channel
    index = json.loads((Path(decoded) / "index.json").read_text())
    ratios = []
    for frame in index["frames"]:
        if frame["illumination"] == "ambient":
            continue  # a Monte Carlo sky at 16 spp: pixel noise that demosaicking averages
        image = np.load(Path(decoded) / frame["image"]).astype(float)
        truth = composed[(frame["view"], frame["illumination"])]
        # off the silhouette and dark paint, where demosaicking mixes neighbours
        interior = minimum_filter(truth.min(axis=2), 5) > 0.1 * truth.max()
        ratios.append(image[interior] / truth[interior])
    pooled = np.concatenate(ratios)
    assert len(pooled) > 200
    np.testing.assert_allclose(np.median(pooled, axis=0), 1.0, atol=0.005)
    # the information floor of the session's two lamps and camera, per vertex and per patch
    floor = information_floor(session)
    assert 0 < floor["rmse_mean"] < 0.2
    # what the camera sees the noise-free estimator reproduces; the rest is its prior's
    assert abs(floor["brightness"]["in_band"] - 1.0) < 0.02
    assert 400 < floor["brightness"]["band_first_nm"] < floor["brightness"]["band_last_nm"] < 700
    # a reflectance.npz on the true mesh: half the vertices 10 % bright, the other half unseen
    gt = session / "ground_truth"
    mesh = load_mesh(gt / "mesh.ply")
    seen = np.arange(len(mesh.vertices)) % 2 == 0
    npz = _write_npz(tmp_path / "r.npz", np.asarray(mesh.vertices), np.asarray(mesh.faces),
                     1.1 * np.load(gt / "reflectance.npy"), seen)  # fmt: skip
    assert reflectance_brightness(npz, session)["all"] == pytest.approx(1.1)
    d65 = floor["colour"][0]
    assert d65["illuminant"] == "D65" and 0 < d65["per_vertex"]["mean"] < 10
    assert len(d65["patches"]) > 1 and d65["patch_max"] >= d65["patch_mean"] > 0


def test_coarse_meshes_are_subdivided_to_a_smooth_scored_surface(tmp_path: Path) -> None:
    import trimesh

    from bench.external_scene import load_mesh

    path = tmp_path / "ico.obj"
    trimesh.creation.icosphere(subdivisions=1).export(path)  # 80 faces: ~60 mm edges at 0.2 m
    mesh = load_mesh(path, 0.2, max_edge_m=0.015)
    assert float(mesh.edges_unique_length.mean()) <= 0.015
    assert len(mesh.faces) == 80 * 4**3  # three Loop steps were needed, no more
    np.testing.assert_allclose(mesh.extents.max(), 0.2)
    np.testing.assert_allclose(mesh.bounds.mean(axis=0), 0.0, atol=1e-12)
    # Loop's limit surface: neighbouring faces meet at small angles (the input's: ~42°)
    assert np.degrees(mesh.face_adjacency_angles.mean()) < 8
    fine = load_mesh(path, 0.2, max_edge_m=1.0)  # already fine enough: left as it is
    assert len(fine.faces) == 80


def test_brightness_splits_the_band_the_camera_sees_from_the_prior() -> None:
    wavelengths = np.arange(400.0, 701.0, 10.0)
    responses = np.zeros((2, 3, len(wavelengths)))
    responses[:, :, 5:25] = 1.0  # 450–640 nm seen
    truth = np.tile(np.linspace(0.2, 0.6, len(wavelengths)), (4, 1))
    estimate = truth.copy()
    estimate[:, :5] *= 1.3
    estimate[:, 25:] *= 1.3
    estimate[0] = np.nan  # unobserved vertices are left out
    b = brightness(estimate, truth, responses, wavelengths)
    assert b["in_band"] == pytest.approx(1.0)
    assert b["out_of_band"] == pytest.approx(1.3)
    assert 1.0 < b["all"] < 1.3
    assert (b["band_first_nm"], b["band_last_nm"]) == (450.0, 640.0)


def test_a_third_lamp_is_a_third_illumination_that_lowers_the_floor(
    shared_data: Path, tmp_path: Path
) -> None:
    """`--third-lamp`: the bulb's r+g+b channels switch a third measured lamp, captured and
    reconstructable like the others; its information floor is below the two lamps'."""
    two = replace(TINY, distance_factors=(1.0,))
    three = replace(two, lamps={**two.lamps, "L3": "Fluence.LED.AnthoSpec"})
    size = Size(width=64, height=48, focal_px=112.0, views=2, spp=4)
    floors = []
    for spec in (two, three):
        session = build_session(spec, size, tmp_path / str(len(spec.lamps)), shared_data,
                                tmp_path / "cache")  # fmt: skip
        raws = sorted((session / "raw").glob("*.dng"))
        assert len(raws) == 2 * len(spec.lamps)
        floors.append(information_floor(session))
    assert any(p.name.endswith("_L3.dng") for p in raws)
    assert floors[1]["rmse_mean"] < 0.9 * floors[0]["rmse_mean"]
    d65 = [f["colour"][0]["per_vertex"]["mean"] for f in floors]
    assert d65[1] < 0.7 * d65[0]


def test_on_surface_colour_scores_only_vertices_on_the_true_surface(tmp_path: Path) -> None:
    from bench.external import ON_SURFACE_M, colour_subsets

    vertices, faces, patch, reflectance, truth = plate_truth(tmp_path)
    # the right colour on the surface; a quarter of the vertices lifted off it, and grey
    lifted = np.arange(len(vertices)) % 4 == 0
    moved = vertices + np.where(lifted, 4 * ON_SURFACE_M, 0.0)[:, None] * np.array([0, 0, 1.0])
    estimate = np.where(lifted[:, None], 0.5, reflectance)
    npz = _write_npz(tmp_path / "r.npz", moved, faces, estimate, np.ones(len(vertices), bool))
    near = colour_subsets(npz, truth)["on_surface"]
    assert near["share"] == pytest.approx(1 - lifted.mean())
    assert near["rmse_mean"] == pytest.approx(0.0, abs=1e-6)
    for report in near["colour"]:
        assert report["per_vertex"]["mean"] == pytest.approx(0.0, abs=1e-3)
        assert [p["vertices"] for p in report["patches"]] == [
            int(np.sum(~lifted & (patch == k))) for k in (0, 1)
        ]
    # the benchmark's colour table shows the row beside the whole reconstruction's
    from bench.external import tables

    stats = {f"{k}_{s}": 0.001 for k in ("acc", "comp") for s in ("mean", "median", "p90")}
    brightness = {"all": 1.0, "in_band": 1.0, "out_of_band": 1.0, "band_first_nm": 420.0,
                  "band_last_nm": 660.0}  # fmt: skip
    other = near["colour"]  # any colour report fills the table's other rows
    result = {
        "scene": "plate", "mesh": "plate.ply", "initial": stats, "final": stats,
        "rmse_mean": 0.1, "rmse_median": 0.1, "oracle_rmse_mean": 0.05, "rmse_per_patch": {0: 0.1},
        "outside_unit_range": 0, "light_offset_error_m": None, "colour": other,
        "on_surface": near, "inside_patches": near, "oracle_colour": other,
        "oracle_inside_patches": near,
        "floor": {"rmse_mean": 0.02, "colour": other, "brightness": brightness},
        "brightness": brightness, "oracle_brightness": brightness,
        "timings_s": {}, "render_s": 1.0, "peak_rss_mb": 1.0,
    }  # fmt: skip
    colour = next(t for t in tables([result]) if t.title.startswith("Colour"))
    row = next(r for r in colour.rows if "true surface" in r[1])
    assert "within 0.5 mm" in row[1] and "(75% of its vertices)" in row[1]
    assert row[3].startswith("0.00 / 0.00")  # ΔE00 D65 per vertex mean / median / p90
    assert sum("1.0 mm or more from a paint edge" in r[1] for r in colour.rows) == 2


def test_colour_inside_patches_leaves_out_the_vertices_at_a_paint_edge(tmp_path: Path) -> None:
    import trimesh

    from bench.external import PAINT_EDGE_M, colour_subsets, paint_edge_distance

    vertices, faces, patch, reflectance, truth = plate_truth(tmp_path)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    # the two columns either side of the border (5 mm apart) are on it; the next ones 5 mm off
    edge = paint_edge_distance(mesh, patch)
    column = np.round(vertices[:, 0] / 0.005).astype(int)
    assert np.all(edge[np.isin(column, (-1, 0))] == 0)
    assert edge[column == 1] == pytest.approx(0.005)
    # a blur across the border: the two columns on it read the mean of both paints
    at_edge = edge < PAINT_EDGE_M
    blurred = np.where(at_edge[:, None], reflectance.mean(axis=0), reflectance)
    npz = _write_npz(tmp_path / "r.npz", vertices, faces, blurred, np.ones(len(vertices), bool))
    subsets = colour_subsets(npz, truth)
    inside, everywhere = subsets["inside_patches"], subsets["on_surface"]  # all on the surface
    assert inside["share"] == pytest.approx(1 - at_edge.mean())
    assert everywhere["share"] == 1.0
    assert inside["colour"][0]["per_vertex"]["mean"] == pytest.approx(0.0, abs=1e-3)
    assert everywhere["colour"][0]["per_vertex"]["mean"] > 0.1


def test_a_patch_seen_only_along_its_border_is_listed_but_not_averaged(tmp_path: Path) -> None:
    from bench._common import colour_cells
    from bench.external import colour_subsets

    vertices, faces, patch, reflectance, truth = plate_truth(tmp_path)
    # patch 1 seen only on its border column, and there read as a mix of both paints
    observed = vertices[:, 0] <= 1e-9
    estimate = np.where((patch == 1)[:, None], reflectance.mean(axis=0), reflectance)
    npz = _write_npz(tmp_path / "r.npz", vertices, faces, estimate, observed)
    seen = colour_subsets(npz, truth)["on_surface"]  # all of the observed vertices
    d65 = seen["colour"][0]
    assert [(p["patch"], p["measured"]) for p in d65["patches"]] == [(0, True), (1, False)]
    assert d65["patches"][1]["delta_e00"] > 1.0
    assert d65["patch_mean"] == pytest.approx(0.0, abs=1e-6)
    assert colour_cells(seen["colour"])[1] == "0.00 / 0.00 (1 of 2)"
