"""run_front on a synthetic session: stages chained, resumable, initial mesh close to the
true surface, subdivided to the image resolution, visibility of every view."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import trimesh
from front_synthetic import RADIUS, build_session, dented_sphere

from core.errors import RigError
from reconstruct.geometry.subdivide import sqrt3_step
from reconstruct.initial_mesh.dense.bright_pixels import GLOSSY_BRIGHT_RATIO
from reconstruct.initial_mesh.dense.mirror import GLOSSY_MIRROR_DEG, MIN_VIEWS
from reconstruct.initial_mesh.dense.patchmatch import PatchMatchConfig
from reconstruct.initial_mesh.dense.poisson import read_mesh
from reconstruct.initial_mesh.repair import defects
from reconstruct.initial_mesh.stage import MeshConfig
from reconstruct.run.front import FrontConfig, _highlight_passes, run_front

FAST = {"mesh": {"voxels": 64}}


def test_front_on_synthetic_session(
    make_session: Callable[..., Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    root = make_session(views=10)
    result = run_front(root, FAST)
    initial = read_mesh(result.initial_mesh_path)
    error = np.abs(np.linalg.norm(initial.vertices, axis=1) - RADIUS)
    print(f"initial mesh: mean distance to the true sphere {error.mean() * 1e3:.2f} mm "
          f"(radius {RADIUS * 1e3:.0f} mm), max {error.max() * 1e3:.2f} mm")
    assert error.mean() < 0.03 * RADIUS
    # at 160x120 the sphere's paint leaves PatchMatch nothing to match: the hull stands in
    info = json.loads((result.recon_dir / "mesh" / "initial.json").read_text())
    assert info["method"] == "visual_hull+poisson (patchmatch matched too few points)"
    assert sorted(result.poses) == list(range(10))
    assert set(result.frames) == {(v, i) for v in range(10) for i in ("white", "red")}
    assert result.frame_path(3, "red").is_file() and result.scale_is_metric
    assert result.skipped_frames == {}
    assert len(result.visibility.indptr) == len(result.mesh.vertices) + 1
    counts = result.visibility.counts()
    assert counts.mean() > 2 and (counts > 0).mean() > 0.95
    fine = json.loads((result.recon_dir / "subdivide" / "subdivide.json").read_text())
    assert fine["mean_edge_after"] <= fine["target_edge"] * np.sqrt(3)
    assert (result.recon_dir / "log.txt").read_text().count("subdivide: ") >= 1
    # a second run finds every stage up to date, whichever way the session's path is spelled
    monkeypatch.chdir(root.parent)
    run_front(Path(root.name), FAST)
    timings = json.loads((result.recon_dir / "timings.json").read_text())
    assert set(timings) == {"decode", "poses", "initial_mesh", "visibility", "subdivide"}
    assert all(t["skipped"] for t in timings.values())


def test_given_initial_mesh_is_subdivided(
    make_session: Callable[..., Path], tmp_path: Path
) -> None:
    root = make_session(views=6, illuminations=("white",))
    coarse = trimesh.creation.icosphere(subdivisions=1, radius=RADIUS)
    path = tmp_path / "coarse.obj"
    coarse.export(path)
    result = run_front(root, {"subdivide": {"target_px": 3.0}}, initial_mesh_file=path)
    info = json.loads((result.recon_dir / "subdivide" / "subdivide.json").read_text())
    assert info["steps"] >= 2
    assert len(result.mesh.faces) == len(coarse.faces) * 3 ** info["steps"]
    assert json.loads((result.recon_dir / "mesh" / "initial.json").read_text())["method"] == "given"


def test_a_broken_initial_mesh_is_repaired_before_subdivision(
    make_session: Callable[..., Path], tmp_path: Path
) -> None:
    """A fin on an edge, a flipped patch, repeated faces and floaters: subdivision used to stop
    on such a mesh ("non-manifold or inconsistently oriented"); the front repairs it first."""
    root = make_session(views=6, illuminations=("white",))
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=RADIUS)
    faces = sphere.faces.copy()
    faces[:12] = faces[:12, ::-1]
    a, b = sphere.faces[100, :2]
    fin = len(sphere.vertices)
    floaters = [trimesh.creation.icosahedron().apply_scale(RADIUS / 50).apply_translation(
        [RADIUS * 2, 0, RADIUS * k / 10]) for k in range(5)]
    pieces = [trimesh.Trimesh(np.vstack([sphere.vertices, 1.3 * sphere.vertices[[a]]]),
                              np.vstack([faces, faces[:20], [[a, b, fin]]])), *floaters]
    offsets = np.cumsum([0] + [len(p.vertices) for p in pieces[:-1]])
    broken = trimesh.Trimesh(np.vstack([p.vertices for p in pieces]),
                             np.vstack([p.faces + k for p, k in zip(pieces, offsets, strict=True)]),
                             process=False)
    with pytest.raises(RigError, match="non-manifold or inconsistently oriented"):
        sqrt3_step(broken.vertices, broken.faces)
    path = tmp_path / "broken.ply"
    broken.export(path)
    result = run_front(root, {"subdivide": {"target_px": 3.0}}, initial_mesh_file=path)
    info = json.loads((result.recon_dir / "mesh" / "initial.json").read_text())
    assert info["watertight"] and len(info["repair"]["actions"]) >= 3, info["repair"]
    assert defects(result.mesh).subdividable and result.mesh.is_watertight
    assert len(result.mesh.faces) > len(sphere.faces)  # it was subdivided


def test_a_mesh_beyond_repair_stops_the_initial_mesh_stage(
    make_session: Callable[..., Path], tmp_path: Path
) -> None:
    root = make_session(views=6, illuminations=("white",))
    path = tmp_path / "box.ply"
    trimesh.creation.box(extents=(RADIUS,) * 3).export(path)  # 12 faces: nothing to refine
    with pytest.raises(RigError, match=r"initial mesh is beyond repair: .*12 faces") as error:
        run_front(root, initial_mesh_file=path)
    assert f"give {path}" in str(error.value) and "\n" not in str(error.value)
    assert not (root / "recon" / "subdivide").exists()


def test_config_errors(tmp_path: Path) -> None:
    with pytest.raises(RigError, match="'optimise' is not known"):
        FrontConfig.from_mapping({"optimise": {}})
    with pytest.raises(RigError, match="voxel"):
        FrontConfig.from_mapping({"mesh": {"voxel": 3}})
    with pytest.raises(RigError, match="mask_dilate_px"):
        FrontConfig.from_mapping({"mesh": {"mask_dilate_px": -1}})
    with pytest.raises(RigError, match="initial mesh"):
        from reconstruct.initial_mesh.stage import load_user_mesh

        load_user_mesh(tmp_path / "nope.ply")


@pytest.mark.slow
def test_patchmatch_recovers_a_concavity_the_hull_cannot(tmp_path: Path) -> None:
    truth = dented_sphere(depth=0.02)
    root = build_session(tmp_path, views=12, illuminations=("white",), size=(200, 150),
                         mesh=truth)
    errors = {}
    for method in ("visual_hull", "patchmatch"):
        result = run_front(root, {"mesh": {"voxels": 64, "method": method}})
        points = read_mesh(result.initial_mesh_path).sample(4000, seed=0)
        distance = np.abs(trimesh.proximity.signed_distance(truth, points))
        errors[method] = distance[points[:, 0] > 0.06].mean()
    print(f"dent (20 mm deep): mean distance {errors['visual_hull'] * 1e3:.2f} mm (hull) -> "
          f"{errors['patchmatch'] * 1e3:.2f} mm (PatchMatch)")
    assert errors["visual_hull"] > 0.003  # the hull bridges the dent
    assert errors["patchmatch"] < 0.5 * errors["visual_hull"]
    info = json.loads((result.recon_dir / "mesh" / "initial.json").read_text())
    assert "near_mirror_pixels" not in info  # a matte object is fused once
    # a glossy one, declared so, seen from 12 views is fused once too: the dent, seen head-on,
    # keeps its gain; the second fusion, without the highlights, runs when the config asks
    glossy = build_session(tmp_path / "glossy", views=12, illuminations=("white",),
                           size=(200, 150), mesh=truth, gloss=0.04)
    result = run_front(glossy, {"mesh": {"voxels": 64}}, glossy=True)
    info = json.loads((result.recon_dir / "mesh" / "initial.json").read_text())
    assert "near_mirror_pixels" not in info
    points = read_mesh(result.initial_mesh_path).sample(4000, seed=0)
    distance = np.abs(trimesh.proximity.signed_distance(truth, points))
    print(f"glossy, fused once: {distance[points[:, 0] > 0.06].mean() * 1e3:.2f} mm")
    assert distance[points[:, 0] > 0.06].mean() < 0.5 * errors["visual_hull"]
    both = {"mirror_deg": 20, "bright_ratio": 1.2}
    result = run_front(glossy, {"mesh": {"voxels": 64, "patchmatch": both}}, glossy=True)
    info = json.loads((result.recon_dir / "mesh" / "initial.json").read_text())
    assert info["near_mirror_pixels"] > 0
    assert info["bright_pixels"] > 0


@pytest.mark.parametrize(
    ("glossy", "views", "named", "expected"),
    [(True, 40, (None, None), (GLOSSY_MIRROR_DEG, GLOSSY_BRIGHT_RATIO)),
     (True, MIN_VIEWS - 1, (None, None), (0.0, 0.0)),
     (False, 40, (None, None), (0.0, 0.0)),
     (True, 12, (15.0, 1.5), (15.0, 1.5)),
     (False, 40, (15.0, None), (15.0, 0.0)),
     (True, 40, (None, 0.0), (GLOSSY_MIRROR_DEG, 0.0))],
)
def test_highlights_are_left_out_of_fusion_on_glossy_objects_seen_from_enough_views(
    glossy: bool, views: int, named: tuple[float | None, float | None],
    expected: tuple[float, float],
) -> None:
    conf = MeshConfig(patchmatch=PatchMatchConfig(mirror_deg=named[0], bright_ratio=named[1]))
    pm = _highlight_passes(conf, glossy, views).patchmatch
    assert (pm.mirror_deg, pm.bright_ratio) == expected


@pytest.mark.parametrize(
    ("optimise", "glossy"),
    [({}, False), ({"gloss": "fit"}, True), ({"highlights": True}, True)],
)
def test_the_pipeline_tells_the_front_end_when_the_object_is_glossy(
    make_session: Callable[..., Path], monkeypatch: pytest.MonkeyPatch, optimise: dict,
    glossy: bool,
) -> None:
    from reconstruct.run import pipeline

    seen = {}

    def front(*args: object, **kwargs: object) -> None:
        seen.update(kwargs)
        raise RigError("stopped after the front end's call", "")

    monkeypatch.setattr(pipeline, "run_front", front)
    with pytest.raises(RigError, match="stopped after"):
        pipeline.run_reconstruction(make_session(views=3), {"optimise": optimise})
    assert seen["glossy"] is glossy
