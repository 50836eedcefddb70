"""The initial mesh's repair: broken meshes come out one oriented, edge-manifold surface
that the √3 subdivision accepts; a mesh beyond repair stops with one line and the numbers."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from core.errors import RigError
from reconstruct.geometry.subdivide import sqrt3_step
from reconstruct.initial_mesh.repair import RepairConfig, defects, joined, repair
from reconstruct.initial_mesh.stage import mesh_config


def sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=3, radius=0.05)


def tetrahedron(apex_y: float) -> trimesh.Trimesh:
    """Outward tetrahedron on the edge (0,0,0)-(1,0,0), apex towards ``apex_y``."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, apex_y, 0], [0, 0, apex_y]], float)
    mesh = trimesh.Trimesh(v, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], process=False)
    trimesh.repair.fix_normals(mesh)
    return mesh


def assert_subdividable(mesh: trimesh.Trimesh) -> None:
    found = defects(mesh)
    assert found.subdividable and found.non_manifold_vertices == 0, found
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    sqrt3_step(mesh.vertices, mesh.faces)  # raises on a shared directed edge


def test_two_tetrahedra_sharing_an_edge_are_remeshed() -> None:
    two = joined([tetrahedron(1.0), tetrahedron(-1.0)])  # the edge is shared
    assert defects(two).non_manifold_edges == 1
    out, report = repair(two)
    assert_subdividable(out)
    assert any("re-meshed" in a for a in report["actions"])
    assert out.volume == pytest.approx(2 / 6, rel=0.1)  # both tetrahedra kept


def test_a_flipped_patch_is_rewound_outward() -> None:
    mesh = sphere()
    faces = mesh.faces.copy()
    faces[:40] = faces[:40, ::-1]
    broken = trimesh.Trimesh(mesh.vertices, faces, process=False)
    assert defects(broken).misoriented_edges > 0
    with pytest.raises(RigError, match="non-manifold or inconsistently oriented"):
        sqrt3_step(broken.vertices, broken.faces)
    out, report = repair(broken)
    assert_subdividable(out)
    assert out.volume == pytest.approx(mesh.volume)
    assert any("re-wound" in a for a in report["actions"])


def test_a_fully_inverted_mesh_is_turned_outward() -> None:
    mesh = sphere()
    out, _ = repair(trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], process=False))
    assert_subdividable(out)


def test_duplicated_faces_are_dropped() -> None:
    mesh = sphere()
    broken = trimesh.Trimesh(mesh.vertices, np.vstack([mesh.faces, mesh.faces[:30]]),
                             process=False)
    out, report = repair(broken)
    assert_subdividable(out)
    assert len(out.faces) == len(mesh.faces)
    assert "30 faces" in report["actions"][0]


def test_a_spray_of_small_pieces_is_dropped() -> None:
    rng = np.random.default_rng(0)
    floaters = [trimesh.creation.icosahedron().apply_scale(0.002).apply_translation(
        rng.uniform(-0.1, 0.1, 3)) for _ in range(40)]
    spray = joined([sphere(), *floaters])
    out, report = repair(spray)
    assert_subdividable(out)
    assert len(out.faces) == len(sphere().faces)
    assert "kept 1 of 41 pieces" in report["actions"]


def test_a_small_hole_is_filled() -> None:
    mesh = sphere()
    holed = trimesh.Trimesh(mesh.vertices, mesh.faces[1:], process=False)
    assert not holed.is_watertight
    out, report = repair(holed)
    assert_subdividable(out)
    assert any("filled holes" in a for a in report["actions"])


def test_two_cones_touching_at_their_tips_are_remeshed() -> None:
    cone = trimesh.creation.cone(0.02, 0.04)
    top = cone.copy().apply_transform(trimesh.transformations.rotation_matrix(np.pi, [1, 0, 0]))
    bowtie = joined([cone, top.apply_translation([0, 0, 0.08])])
    assert defects(bowtie).non_manifold_vertices == 1
    out, _ = repair(bowtie)
    assert_subdividable(out)


def test_a_sound_mesh_is_left_as_it_is() -> None:
    mesh = sphere()
    out, report = repair(mesh)
    assert report["actions"] == []
    np.testing.assert_array_equal(out.faces, mesh.faces)


def test_an_open_mesh_keeps_its_outline() -> None:
    """A cap (a scan's open bottom) is no defect: the subdivision keeps boundaries."""
    mesh = sphere()
    cap = trimesh.Trimesh(mesh.vertices, mesh.faces[mesh.triangles_center[:, 2] > 0])
    cap.remove_unreferenced_vertices()
    out, report = repair(cap)
    assert defects(out).subdividable and defects(out).boundary_edges > 0
    assert report["actions"] == []


def test_a_mesh_far_from_the_hull_is_replaced_by_it() -> None:
    hull = sphere()
    astray = sphere().apply_translation([0.5, 0, 0])
    out, report = repair(astray, hull=hull, voxel=0.001)
    np.testing.assert_allclose(out.bounds, hull.bounds)
    assert "replaced by the visual hull" in report["actions"][-1]


def test_a_mesh_beyond_repair_stops_with_the_numbers() -> None:
    collapsed = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 0, 0]], [[0, 1, 2]], process=False)
    with pytest.raises(RigError, match="no usable face") as error:
        repair(collapsed)
    assert "--initial-mesh" in str(error.value) and "\n" not in str(error.value)
    with pytest.raises(RigError, match=r"beyond repair: 0 non-manifold edges.* 4 faces "
                       r"\(mesh.repair.min_faces: 20\)") as error:
        repair(tetrahedron(1.0))
    assert "more views" in str(error.value)


def test_config_bounds_are_checked() -> None:
    assert mesh_config({"repair": {"min_faces": 100}}).repair == RepairConfig(min_faces=100)
    with pytest.raises(RigError, match="keep_fraction"):
        mesh_config({"repair": {"keep_fraction": 2.0}})


def test_two_spheres_touching_at_a_point_lose_a_few_faces_not_their_shape() -> None:
    """A vertex joining two fans costs the faces of the smaller fan (a small hole), not a
    re-mesh of everything."""
    one = sphere()
    top = int(np.argmax(one.vertices[:, 2]))
    other = sphere().apply_translation(one.vertices[top] - one.vertices[np.argmin(
        one.vertices[:, 2])])
    touching = joined([one, other])
    assert defects(touching).non_manifold_vertices == 1
    out, report = repair(touching)
    assert defects(out).subdividable and defects(out).non_manifold_vertices == 0
    assert any(a.startswith("dropped") for a in report["actions"]), report
    assert 0 < 2 * len(one.faces) - len(out.faces) <= 10


def test_a_face_of_zero_area_in_a_closed_mesh_stays() -> None:
    """Clamping the hull to the board (z >= 0) leaves faces of zero area on three distinct
    corners; they still close the surface, and dropping them would open holes."""
    mesh = sphere()
    a, b, c = mesh.faces[0]
    vertices = mesh.vertices.copy()
    vertices[c] = (vertices[a] + vertices[b]) / 2  # face 0 becomes a sliver of no area
    sliver = trimesh.Trimesh(vertices, mesh.faces, process=False)
    assert not sliver.nondegenerate_faces()[0]
    out, report = repair(sliver)
    assert out.is_watertight and defects(out).subdividable
    assert len(out.faces) == len(mesh.faces) and report["actions"] == []
