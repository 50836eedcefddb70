"""Visibility stage: V(i), the views that see vertex i (paper Sec. 3.2), and shadow masks.

A view sees a vertex when the vertex projects inside its image, faces the camera and the
segment vertex -> camera centre crosses no triangle (Embree through
:class:`reconstruct.model.raycast.RayCaster`). Stored as CSR (vertex -> view indices) in
``visibility.npz``: ``indptr`` (N+1,), ``indices`` (nnz,) of views, ``depth`` (nnz,) the
vertex's depth in that view, and ``views`` (the view numbers in column order).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from core.config import bounded, from_mapping
from core.files import write_bytes_atomically
from reconstruct.initial_mesh.dense.poisson import read_mesh
from reconstruct.model.camera import Intrinsics, Pose, project
from reconstruct.model.raycast import RayCaster
from reconstruct.poses.output import PoseSet
from reconstruct.poses.output import load as load_poses
from reconstruct.stages.progress import track
from reconstruct.stages.resumable import run_stage

log = logging.getLogger("reconstruct.geometry.visibility")

FILE = "visibility.npz"


@dataclass(frozen=True)
class VisibilityConfig:
    """``eps``: self-hit tolerance relative to the scene size; ``margin_px``: border of the
    image treated as outside; ``min_cos``: least cosine between normal and view direction."""

    eps: float = bounded(1e-4, above=0.0, max=1.0)
    margin_px: float = bounded(1.0, min=0.0, max=10_000.0)
    min_cos: float = bounded(0.0, min=-1.0, max=1.0)


@dataclass
class Visibility:
    """CSR vertex -> views. ``views[indices[indptr[i]:indptr[i+1]]]`` are the views of i."""

    indptr: np.ndarray
    indices: np.ndarray
    depth: np.ndarray
    views: np.ndarray

    def of(self, vertex: int) -> np.ndarray:
        """View numbers that see ``vertex``."""
        return self.views[self.indices[self.indptr[vertex] : self.indptr[vertex + 1]]]

    def pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """(vertex, view column) of every visible pair, in CSR order."""
        counts = np.diff(self.indptr)
        return np.repeat(np.arange(len(counts)), counts), self.indices

    def counts(self) -> np.ndarray:
        return np.diff(self.indptr)

    def matrix(self, views: Sequence[int]) -> np.ndarray:
        """Bool (vertices, len(views)): whether each of ``views`` sees each vertex — the form
        the optimiser takes; views not in the file see nothing."""
        column = {int(v): k for k, v in enumerate(views)}
        out = np.zeros((len(self.indptr) - 1, len(views)), dtype=bool)
        rows, cols = self.pairs()
        view_of = np.asarray(self.views)[cols]
        known = np.isin(view_of, list(column))
        out[rows[known], [column[int(v)] for v in view_of[known]]] = True
        return out

    def save(self, path: Path) -> None:
        np.savez_compressed(path, indptr=self.indptr, indices=self.indices, depth=self.depth,
                            views=self.views)

    @classmethod
    def load(cls, path: Path) -> Visibility:
        with np.load(path) as data:
            return cls(data["indptr"], data["indices"], data["depth"], data["views"])


def compute_visibility(
    mesh: trimesh.Trimesh,
    intrinsics: Mapping[int, Intrinsics],
    poses: Mapping[int, Pose],
    conf: VisibilityConfig = VisibilityConfig(),
    caster: RayCaster | None = None,
) -> Visibility:
    """V(i) for every vertex, vectorised over vertices for each view."""
    caster = caster or RayCaster(mesh.vertices, mesh.faces)
    points = np.asarray(mesh.vertices, dtype=float)
    normals = np.asarray(mesh.vertex_normals, dtype=float)
    views = np.array(sorted(poses), dtype=np.int64)
    rows_l, cols_l, depth_l = [], [], []
    for col, view in enumerate(track(views.tolist(), "visibility: ray casting")):
        pose, intr = poses[int(view)], intrinsics[int(view)]
        uv = project(intr, pose, points)
        z = pose.to_camera(points)[:, 2]
        to_cam = pose.center - points
        cos = np.einsum("ij,ij->i", normals, to_cam) / np.linalg.norm(to_cam, axis=1)
        cand = np.flatnonzero(intr.in_image(uv, conf.margin_px) & (z > 0) & (cos > conf.min_cos))
        seen = cand[~caster.occluded(points[cand], pose.center, conf.eps, normals[cand])]
        rows_l.append(seen)
        cols_l.append(np.full(len(seen), col))
        depth_l.append(z[seen])
    rows, cols, z_all = (np.concatenate(a) for a in (rows_l, cols_l, depth_l))
    order = np.lexsort((cols, rows))
    rows, cols, z_all = rows[order], cols[order], z_all[order]
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=len(points)))])
    return Visibility(indptr, cols.astype(np.int32), z_all, views)


def _visibility(mesh_path: Path, posed: PoseSet, conf: VisibilityConfig, out_dir: Path) -> None:
    mesh = read_mesh(mesh_path)
    intrinsics, poses, _ = posed
    vis = compute_visibility(mesh, intrinsics, poses, conf)
    vis.save(out_dir / FILE)
    counts = vis.counts()
    summary = {"vertices": len(counts), "pairs": int(counts.sum()),
               "mean_views_per_vertex": float(counts.mean()),
               "unseen_vertices": int((counts == 0).sum())}
    write_bytes_atomically(out_dir / "visibility.json", json.dumps(summary, indent=1).encode())
    log.info("visibility: %.1f views per vertex on average, %d vertices unseen",
             summary["mean_views_per_vertex"], summary["unseen_vertices"])


def run(
    conf: VisibilityConfig | Mapping[str, Any],
    mesh_path: Path,
    poses_dir: Path,
    out_dir: Path,
    posed: PoseSet | None = None,
) -> Path:
    """V(i) of ``mesh_path``'s vertices into ``out_dir/visibility.npz`` (resumable);
    ``posed``: the poses stage's output when the caller has loaded it."""
    conf = from_mapping(VisibilityConfig, conf, "config", "visibility")
    inputs = [mesh_path, poses_dir / "images.txt", poses_dir / "cameras.txt"]
    run_stage("visibility", asdict(conf), inputs, out_dir,
              lambda: _visibility(mesh_path, posed or load_poses(poses_dir), conf, out_dir))
    return out_dir / FILE
