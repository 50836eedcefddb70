"""Oriented points -> watertight mesh with pycolmap's Poisson reconstruction (CPU): the one
Poisson of the initial-mesh methods (dense multi-view stereo and the projector's Gray code).

``pycolmap.poisson_meshing(input_path, output_path, options)`` reads a PLY point cloud with
``nx ny nz`` normals and writes a mesh PLY; ``options.trim`` removes low-density parts.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pycolmap
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from core.errors import RigError
from reconstruct.stages.resumable import quiet_colmap


def read_mesh(path: Path, process: bool = False) -> trimesh.Trimesh:
    """One triangle mesh from a file (scenes merged); ``process=False`` keeps vertex order."""
    mesh = trimesh.load(path, force="mesh", process=process)
    if not isinstance(mesh, trimesh.Trimesh):
        raise RigError(f"{path} holds no triangle mesh", "give a triangle mesh file")
    return mesh


def write_oriented_ply(path: Path, points: np.ndarray, normals: np.ndarray) -> None:
    """Binary little-endian PLY with x y z nx ny nz (float32) and no faces."""
    cloud = trimesh.Trimesh(
        vertices=points, faces=np.zeros((0, 3), np.int64), vertex_normals=normals, process=False
    )
    path.write_bytes(trimesh.exchange.ply.export_ply(cloud, encoding="binary", vertex_normal=True))


def poisson_mesh(
    points: np.ndarray,
    normals: np.ndarray,
    depth: int,
    trim: float,
    num_threads: int = -1,
    *,
    largest_only: bool = True,
    trim_option: str = "mesh.poisson_trim (mesh.patchmatch.poisson_trim with method patchmatch)",
) -> trimesh.Trimesh:
    """Screened Poisson surface of oriented points: octree ``depth``, density ``trim``; with
    ``largest_only`` only the largest connected piece is kept. ``trim_option`` names the
    setting that ``trim`` came from, for the hint when nothing is left."""
    if len(points) < 4:  # pycolmap's trimmer dies on an empty octree instead of raising
        raise RigError(
            f"Poisson meshing was given {len(points)} points",
            "check the dense point cloud (masks, texture) or give --initial-mesh",
        )
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "points.ply", Path(tmp) / "mesh.ply"
        write_oriented_ply(src, points, normals)
        options = pycolmap.PoissonMeshingOptions()
        options.depth = depth
        options.trim = trim
        options.color = False
        options.num_threads = num_threads
        with quiet_colmap():
            pycolmap.poisson_meshing(src, dst, options)
        if not dst.is_file():
            raise RigError("Poisson meshing produced no mesh", "check the point cloud")
        mesh = read_mesh(dst, process=True)
    if len(mesh.faces) == 0:
        raise RigError("Poisson meshing produced an empty mesh", f"lower {trim_option}")
    return largest_component(mesh) if largest_only else mesh


def largest_component(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The connected piece with the most faces (Poisson leaves small floaters)."""
    adjacency = np.asarray(mesh.face_adjacency)
    n = len(mesh.faces)
    graph = coo_matrix((np.ones(len(adjacency)), (adjacency[:, 0], adjacency[:, 1])), (n, n))
    count, labels = connected_components(graph, directed=False)
    if count > 1:
        keep = labels == np.argmax(np.bincount(labels))
        mesh = trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False)
    mesh.remove_unreferenced_vertices()
    return mesh
