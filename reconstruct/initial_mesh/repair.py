"""Repair an initial mesh before subdivision, or say in one line why it cannot be used.

The √3 subdivision needs one consistently oriented, edge-manifold surface; a Poisson mesh of
a sparse cloud or a mesh from another tool often is not. The order, cheapest first:

1. clean: merge duplicate vertices, drop collapsed (a corner repeated) and repeated faces;
2. keep the pieces that carry the object (at least ``keep_fraction`` of the largest piece's
   area; a spray of floaters goes);
3. orient each piece outward (``trimesh.repair.fix_normals``) and fill single-triangle and
   quad holes (``trimesh.repair.fill_holes``);
4. still non-manifold (edges shared by more than two faces, vertices joining separate fans):
   drop the faces at those few places (small holes; the subdivision keeps boundaries), as
   long as that costs at most ``max_dropped`` of the faces;
5. otherwise re-mesh oriented samples of its surface with the project's Poisson, then check
   again.

A mesh whose median vertex lies more than ``max_hull_distance`` voxels from the visual hull
(when one is known) is replaced by the hull. One still non-manifold, or with fewer than
``min_faces`` faces, raises :class:`RigError` with the numbers.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from core.config import bounded
from core.errors import RigError
from reconstruct.initial_mesh.dense.poisson import poisson_mesh

FIX = "capture more views around the object, raise mesh.voxels, or give --initial-mesh FILE"


@dataclass(frozen=True)
class RepairConfig:
    """``keep_fraction``: pieces smaller than this share of the largest piece's area are
    dropped; ``min_faces``: fewer faces than this after repair is no surface to refine;
    ``max_dropped``: the largest share of faces dropped at non-manifold places before the
    mesh is re-meshed instead; ``remesh_depth``: Poisson octree depth of a re-mesh;
    ``remesh_samples``: surface points it is given; ``max_hull_distance``: the most the
    median vertex may lie from the visual hull, in hull voxels."""

    keep_fraction: float = bounded(0.1, min=0.0, max=1.0)
    min_faces: int = bounded(20, min=4, max=10_000_000)
    remesh_depth: int = bounded(8, min=4, max=12)
    remesh_samples: int = bounded(100_000, min=1000, max=10_000_000)
    max_dropped: float = bounded(0.01, min=0.0, max=1.0)
    max_hull_distance: float = bounded(10.0, above=0.0, max=1e6)


@dataclass(frozen=True)
class Defects:
    """What stops a mesh from being subdivided, counted."""

    non_manifold_edges: int
    misoriented_edges: int
    non_manifold_vertices: int
    components: int
    boundary_edges: int

    @property
    def subdividable(self) -> bool:
        return not (self.non_manifold_edges or self.misoriented_edges
                    or self.non_manifold_vertices)


def defects(mesh: trimesh.Trimesh) -> Defects:
    """Count the defects of ``mesh`` as it will be read back (duplicate vertices merged)."""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    n = max(len(mesh.vertices), 1)
    a, b = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    # an edge as one integer: a 1-D unique is many times faster than a row-wise one
    _, sorted_counts = np.unique(np.minimum(a, b) * n + np.maximum(a, b), return_counts=True)
    _, directed_counts = np.unique(a * n + b, return_counts=True)
    return Defects(
        non_manifold_edges=int((sorted_counts > 2).sum()),
        misoriented_edges=int((directed_counts > 1).sum()),
        non_manifold_vertices=int(non_manifold_vertices(mesh).sum()),
        components=_components(mesh)[0],
        boundary_edges=int((sorted_counts == 1).sum()),
    )


def _components(mesh: trimesh.Trimesh) -> tuple[int, np.ndarray]:
    """Pieces joined across edges two faces share (a non-manifold edge joins nothing)."""
    n = len(mesh.faces)
    adjacency = np.asarray(mesh.face_adjacency).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(adjacency)), (adjacency[:, 0], adjacency[:, 1])), (n, n))
    count, labels = connected_components(graph, directed=False)
    return int(count), labels


def corner_fans(mesh: trimesh.Trimesh) -> np.ndarray:
    """Per face corner (``3 * face + k``): a label shared by the corners of one fan of faces
    around their vertex (joined across the edges through it)."""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    pairs = np.asarray(mesh.face_adjacency).reshape(-1, 2)
    edges = np.asarray(mesh.face_adjacency_edges).reshape(-1, 2)
    corners = [
        3 * pairs[:, side] + np.argmax(faces[pairs[:, side]] == v[:, None], axis=1)
        for v in edges.T
        for side in (0, 1)
    ]
    a = np.concatenate(corners[0::2])
    b = np.concatenate(corners[1::2])
    graph = coo_matrix((np.ones(len(a)), (a, b)), (faces.size,) * 2)
    return np.asarray(connected_components(graph, directed=False)[1])


def minor_fan_corners(mesh: trimesh.Trimesh) -> np.ndarray:
    """Per face corner: it lies in a fan other than its vertex's largest (the corners that
    make the vertex non-manifold)."""
    labels = corner_fans(mesh)
    vertex = np.asarray(mesh.faces, dtype=np.int64).ravel()
    size = np.bincount(labels)[labels]
    key = size * (labels.max() + 1) + labels  # the largest fan, ties to the higher label
    best = np.zeros(len(mesh.vertices), np.int64)
    np.maximum.at(best, vertex, key)
    return np.asarray(key != best[vertex])


def non_manifold_vertices(mesh: trimesh.Trimesh) -> np.ndarray:
    """Per vertex: its faces form more than one fan (two cones touching at their tips)."""
    minor = minor_fan_corners(mesh)
    flags = np.zeros(len(mesh.vertices), bool)
    flags[np.asarray(mesh.faces).ravel()[minor]] = True
    return flags


def non_manifold_faces(mesh: trimesh.Trimesh) -> np.ndarray:
    """Per face: on an edge more than two faces share, on a directed edge two faces share
    (wound against its neighbour), or in a minor fan of a non-manifold vertex."""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    n = max(len(mesh.vertices), 1)
    a, b = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    bad = minor_fan_corners(mesh)
    for key, most in ((np.minimum(a, b) * n + np.maximum(a, b), 2), (a * n + b, 1)):
        _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
        bad |= counts[inverse] > most
    return np.asarray(bad.reshape(-1, 3).any(axis=1))


def clean(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Duplicate vertices merged, collapsed faces (a corner repeated) and repeated faces and
    loose vertices gone. Faces of zero area on three distinct corners stay: dropping them
    opens holes in a closed mesh (a hull flattened onto the board has many)."""
    out = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=True)
    f = out.faces
    out.update_faces((f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0]))
    out.update_faces(out.unique_faces())
    out.remove_unreferenced_vertices()
    return out


def object_pieces(mesh: trimesh.Trimesh, keep_fraction: float) -> list[trimesh.Trimesh]:
    """The pieces with at least ``keep_fraction`` of the largest piece's area."""
    count, labels = _components(mesh)
    area = np.bincount(labels, mesh.area_faces, count)
    keep = np.flatnonzero(area >= keep_fraction * area.max())
    pieces = [trimesh.Trimesh(mesh.vertices, mesh.faces[labels == k]) for k in keep]
    for piece in pieces:
        piece.remove_unreferenced_vertices()
    return pieces


def joined(pieces: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """The pieces as one mesh, duplicate vertices merged (as the subdivide stage reads it)."""
    offsets = np.cumsum([0] + [len(p.vertices) for p in pieces[:-1]])
    return trimesh.Trimesh(
        np.vstack([p.vertices for p in pieces]),
        np.vstack([p.faces + k for p, k in zip(pieces, offsets, strict=True)]),
        process=True,
    )


def oriented(piece: trimesh.Trimesh) -> trimesh.Trimesh:
    """One piece wound consistently, outward, with its small holes filled."""
    piece = trimesh.Trimesh(piece.vertices, piece.faces, process=True)
    trimesh.repair.fix_normals(piece, multibody=True)
    trimesh.repair.fill_holes(piece)
    return piece


def remesh(mesh: trimesh.Trimesh, conf: RepairConfig) -> trimesh.Trimesh:
    """Poisson surface of oriented samples of ``mesh`` (untrimmed: closed, one piece)."""
    points, face = trimesh.sample.sample_surface_even(mesh, conf.remesh_samples, seed=0)
    if len(points) < 4:  # sample_surface_even rejects too-close points on a tiny mesh
        points, face = trimesh.sample.sample_surface(mesh, conf.remesh_samples, seed=0)
    return poisson_mesh(points, mesh.face_normals[face], conf.remesh_depth, 0.0, 1)


def drop_non_manifold(
    mesh: trimesh.Trimesh, conf: RepairConfig, report: dict[str, Any]
) -> trimesh.Trimesh:
    """``mesh`` without the faces at its non-manifold places when they are few (a sliver
    removed at a rim leaves two fans on a vertex), else its Poisson re-mesh; the action goes
    into ``report``."""
    out, dropped = mesh, 0
    for _ in range(3):  # dropping faces can leave a vertex joining two fans
        bad = non_manifold_faces(out)
        if not bad.any():
            break
        dropped += int(bad.sum())
        out = trimesh.Trimesh(out.vertices, out.faces[~bad])
        out.remove_unreferenced_vertices()
        if len(out.faces) == 0:
            break
        out = joined(object_pieces(out, conf.keep_fraction))
    if dropped <= conf.max_dropped * len(mesh.faces) and len(out.faces) and (
        defects(out).subdividable
    ):
        report["actions"].append(f"dropped {dropped} faces at non-manifold edges or vertices")
        return out
    report["actions"].append(
        f"re-meshed by Poisson (non-manifold at {dropped} faces after cleaning)")
    return oriented(remesh(mesh, conf))


def hull_distance(mesh: trimesh.Trimesh, hull: trimesh.Trimesh) -> float:
    """Median distance of the mesh's vertices to the nearest hull vertex."""
    return float(np.median(cKDTree(np.asarray(hull.vertices)).query(mesh.vertices)[0]))


def repair(
    mesh: trimesh.Trimesh,
    conf: RepairConfig | None = None,
    hull: trimesh.Trimesh | None = None,
    voxel: float | None = None,
    fix: str = FIX,
) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """A subdividable mesh from ``mesh`` and what was done to it; with the visual ``hull``
    and its ``voxel`` size, also how far the mesh lies from it. Raises :class:`RigError`
    with ``fix`` as the hint when the mesh is beyond repair."""
    conf = conf or RepairConfig()
    found = defects(mesh)
    report: dict[str, Any] = {"found": asdict(found), "actions": []}
    out = clean(mesh)
    if (len(out.vertices), len(out.faces)) != (len(mesh.vertices), len(mesh.faces)):
        report["actions"].append(
            f"cleaned: {len(mesh.vertices) - len(out.vertices)} vertices and "
            f"{len(mesh.faces) - len(out.faces)} faces (repeated, collapsed) removed")
    if len(out.faces) == 0:
        raise RigError(f"the initial mesh has no usable face ({len(mesh.faces)} faces, all "
                       "collapsed or repeated)", fix)
    pieces = object_pieces(out, conf.keep_fraction)
    count = _components(out)[0]
    if len(pieces) < count:
        report["actions"].append(f"kept {len(pieces)} of {count} pieces")
    kept = defects(joined(pieces))
    out = joined([oriented(p) for p in pieces])
    now = defects(out)
    if kept.misoriented_edges > now.misoriented_edges:
        report["actions"].append(f"re-wound ({kept.misoriented_edges} edges ran the same way "
                                 "in both faces)")
    if kept.boundary_edges > now.boundary_edges:
        report["actions"].append(f"filled holes ({kept.boundary_edges - now.boundary_edges} "
                                 "boundary edges closed)")
    if not now.subdividable:
        out = drop_non_manifold(out, conf, report)
        now = defects(out)
    left = now
    report["result"] = asdict(left)
    if hull is not None and voxel:
        distance = hull_distance(out, hull)
        report["median_hull_distance_voxels"] = round(distance / voxel, 2)
        if distance > conf.max_hull_distance * voxel:
            # the surface went astray: the hull is the nearest mesh known to hold the object
            out, hull_report = repair(hull, conf)
            report["actions"].append(
                f"replaced by the visual hull (median vertex {distance / voxel:.1f} voxels "
                "from it)")
            return out, report | {"result": hull_report["result"]}
    if left.subdividable and len(out.faces) >= conf.min_faces:
        return out, report
    raise RigError(
        f"the initial mesh is beyond repair: {left.non_manifold_edges} non-manifold edges, "
        f"{left.non_manifold_vertices} non-manifold vertices, {left.components} pieces, "
        f"{len(out.vertices)} points, {len(out.faces)} faces (mesh.repair.min_faces: "
        f"{conf.min_faces})", fix,
    )
