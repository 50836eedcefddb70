"""Subdivide stage: √3 subdivision (Kobbelt 2000) to the density the images can resolve.

One step inserts a vertex at every face centroid, joins it to the face's corners and flips
every original edge, so a closed mesh with V vertices and F faces becomes V + F vertices and
3F faces; two steps are a triadic split (edge lengths / 3). Old vertices are smoothed with
``p' = (1 - n β_n) p + β_n Σ neighbours``, ``β_n = (4 - 2 cos(2π/n)) / (9n)``.

Boundaries: boundary edges are kept (not flipped; their face gives one triangle instead of
two) and boundary vertices stay fixed. This is simpler than Kobbelt's two-step boundary rule
and keeps an open mesh's outline exactly where the initial mesh put it.

The stage subdivides until the mean edge length is at most ``target_px`` pixels in the
views (edge ≈ target_px · depth / focal, median over visible vertex-view pairs; the views'
decoded frames, whose pyramid level :mod:`reconstruct.stages.resolution` chose) or a target
edge given in metres, then recomputes visibility on the final mesh. A mesh already finer
than that (a dense MVS mesh from Poisson) is first coarsened to the target by quadric
decimation (``decimate``): vertices closer than the images resolve add unknowns and memory to
the joint optimisation, not detail.
Outputs in ``recon/subdivide/``: ``mesh.ply``, ``visibility.npz``, ``subdivide.json``.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from core.config import bounded, from_mapping
from core.errors import RigError
from core.files import write_bytes_atomically
from reconstruct.geometry.visibility import FILE as VIS_FILE
from reconstruct.geometry.visibility import Visibility, VisibilityConfig, compute_visibility
from reconstruct.initial_mesh.dense.poisson import largest_component, read_mesh
from reconstruct.poses.output import PoseSet
from reconstruct.poses.output import load as load_poses
from reconstruct.stages.resumable import run_stage

log = logging.getLogger("reconstruct.geometry.subdivide")

MESH = "mesh.ply"


@dataclass(frozen=True)
class SubdivideConfig:
    """``target_px``: wanted mean edge length in pixels; ``max_steps``/``max_faces`` cap the
    result; ``decimate``: coarsen a mesh whose mean edge is below ``decimate_below`` × the
    target to the target first."""

    target_px: float = bounded(2.0, above=0.0, max=10_000.0)
    max_steps: int = bounded(6, min=0, max=20)
    max_faces: int = bounded(2_000_000, min=1, max=100_000_000)
    decimate: bool = True
    decimate_below: float = bounded(0.8, min=0.0, max=1.0)


def beta(valence: np.ndarray) -> np.ndarray:
    """Kobbelt's smoothing weight per neighbour, β_n = (4 - 2 cos(2π/n)) / (9n)."""
    n = np.maximum(np.asarray(valence, dtype=float), 1.0)
    return (4.0 - 2.0 * np.cos(2.0 * np.pi / n)) / (9.0 * n)


def sqrt3_step(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One √3 step on a consistently oriented, edge-manifold triangle mesh."""
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces, dtype=np.int64)
    n, m = len(v), len(f)
    a, b = f.ravel(), f[:, [1, 2, 0]].ravel()
    face = np.repeat(np.arange(m), 3)
    key = a * n + b
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    if np.any(sorted_key[1:] == sorted_key[:-1]):
        raise RigError(
            "the mesh is non-manifold or inconsistently oriented (a directed edge is shared)",
            "repair it (e.g. trimesh.repair.fix_winding, or remesh) before subdividing",
        )
    twin_key = b * n + a
    pos = np.minimum(np.searchsorted(sorted_key, twin_key), len(key) - 1)
    has_twin = sorted_key[pos] == twin_key
    twin_face = face[order[pos]]
    inner = has_twin & (a < b)
    c1, c2 = n + face[inner], n + twin_face[inner]
    ai, bi = a[inner], b[inner]
    border = ~has_twin
    new_faces = np.concatenate(
        [
            np.stack([ai, c2, c1], axis=1),
            np.stack([c2, bi, c1], axis=1),
            np.stack([a[border], b[border], n + face[border]], axis=1),
        ]
    )
    # smoothing of the old vertices over their one-ring (each undirected edge once)
    ea = np.concatenate([ai, a[border]])
    eb = np.concatenate([bi, b[border]])
    valence = np.bincount(ea, minlength=n) + np.bincount(eb, minlength=n)
    ring = np.stack(
        [np.bincount(ea, v[eb, k], n) + np.bincount(eb, v[ea, k], n) for k in range(3)], axis=1
    )
    w = beta(valence)
    smoothed = (1.0 - valence * w)[:, None] * v + w[:, None] * ring
    fixed = np.zeros(n, bool)
    fixed[a[border]] = True
    fixed[b[border]] = True
    fixed |= valence == 0
    smoothed[fixed] = v[fixed]
    return np.concatenate([smoothed, v[f].mean(axis=1)]), new_faces


def steps_for(
    mean_edge: float, target_edge: float, faces: int, max_steps: int, max_faces: int
) -> int:
    """Fewest √3 steps (each shrinks edges by √3, triples faces) to reach ``target_edge``."""
    steps = 0
    while (
        mean_edge / np.sqrt(3.0) ** steps > target_edge
        and steps < max_steps
        and faces * 3 ** (steps + 1) <= max_faces
    ):
        steps += 1
    return steps


def target_edge_length(
    visibility: Visibility, focal_px: Mapping[int, float], target_px: float
) -> float:
    """target_px · depth / focal, median over the visible (vertex, view) pairs."""
    if len(visibility.indices) == 0:
        raise RigError(
            "no vertex of the initial mesh is visible in any view",
            "the mesh and the poses disagree: check --initial-mesh is in the poses' frame",
        )
    f = np.array([focal_px[int(v)] for v in visibility.views])[visibility.indices]
    return float(target_px * np.median(visibility.depth / f))


def mean_edge(mesh: trimesh.Trimesh) -> float:
    return float(mesh.edges_unique_length.mean())


def decimate(mesh: trimesh.Trimesh, edge: float, target_edge: float) -> trimesh.Trimesh:
    """Quadric decimation (fast-simplification) to a mean edge of about ``target_edge`` (the
    face count scales with the inverse square of the edge length; the result lands within
    ~15 % of the target, and no √3 step follows it). The collapses leave a few non-manifold
    edges (~0.1 % of faces on a Poisson mesh); their faces are dropped, leaving small holes,
    so the mesh stays one consistently oriented, edge-manifold piece."""
    faces = max(4, int(len(mesh.faces) * (edge / target_edge) ** 2))
    coarse = mesh.simplify_quadric_decimation(face_count=faces)
    bad = non_manifold_faces(coarse)
    if bad.any():
        coarse = trimesh.Trimesh(coarse.vertices, coarse.faces[~bad], process=True)
    coarse = largest_component(coarse)
    trimesh.repair.fix_winding(coarse)
    return coarse


def non_manifold_faces(mesh: trimesh.Trimesh) -> np.ndarray:
    """Faces on an edge that more than two faces share, or on a directed edge that two share
    (inconsistent orientation)."""
    bad = np.zeros(len(mesh.faces), bool)
    for edges, most in ((np.sort(mesh.edges, axis=1), 2), (mesh.edges, 1)):
        _, inverse, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
        bad[np.flatnonzero(counts[inverse.ravel()] > most) // 3] = True
    return bad


def subdivide(mesh: trimesh.Trimesh, steps: int) -> trimesh.Trimesh:
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    for _ in range(steps):
        v, f = sqrt3_step(v, f)
    return trimesh.Trimesh(v, f, process=False)


def _subdivide(
    mesh_path: Path, vis_path: Path, posed: PoseSet, conf: SubdivideConfig,
    vis_conf: VisibilityConfig, out_dir: Path, target_m: float | None,
) -> None:
    mesh = read_mesh(mesh_path, process=True)
    trimesh.repair.fix_winding(mesh)
    intrinsics, poses, _ = posed
    target = target_m if target_m is not None else target_edge_length(
        Visibility.load(vis_path), {v: float(i.K[0, 0]) for v, i in intrinsics.items()},
        conf.target_px,
    )
    before = mean_edge(mesh)
    decimated_from = None
    if conf.decimate and before < conf.decimate_below * target:
        decimated_from = len(mesh.vertices)
        mesh = decimate(mesh, before, target)
        log.info("subdivide: decimated %d -> %d vertices (mean edge %.4g -> %.4g)",
                 decimated_from, len(mesh.vertices), before, mean_edge(mesh))
    steps = 0 if decimated_from else steps_for(
        before, target, len(mesh.faces), conf.max_steps, conf.max_faces
    )
    fine = subdivide(mesh, steps)
    fine.export(out_dir / MESH)
    vis = compute_visibility(fine, intrinsics, poses, vis_conf)
    vis.save(out_dir / VIS_FILE)
    summary = {
        "steps": steps, "target_edge": target, "mean_edge_before": before,
        "decimated_from_vertices": decimated_from,
        "mean_edge_after": mean_edge(fine), "vertices": len(fine.vertices),
        "faces": len(fine.faces), "mean_views_per_vertex": float(vis.counts().mean()),
    }
    write_bytes_atomically(out_dir / "subdivide.json", json.dumps(summary, indent=1).encode())
    log.info("subdivide: %d √3 steps, mean edge %.4g -> %.4g (target %.4g), %d vertices",
             steps, before, summary["mean_edge_after"], target, len(fine.vertices))


def run(
    conf: SubdivideConfig | Mapping[str, Any],
    mesh_path: Path,
    vis_path: Path,
    poses_dir: Path,
    out_dir: Path,
    vis_conf: VisibilityConfig | Mapping[str, Any] | None = None,
    posed: PoseSet | None = None,
    target_m: float | None = None,
) -> Path:
    """Subdivided mesh and its visibility into ``out_dir`` (resumable); returns the mesh.
    ``posed``: the poses stage's output when the caller has loaded it; ``target_m``: the
    target edge in metres (instead of ``conf.target_px``)."""
    conf = from_mapping(SubdivideConfig, conf, "config", "subdivide")
    vconf = from_mapping(VisibilityConfig, vis_conf, "config", "visibility")
    inputs = [mesh_path, vis_path, poses_dir / "images.txt", poses_dir / "cameras.txt"]
    settings = asdict(conf) | {"visibility": asdict(vconf)}
    if target_m is not None:
        settings["target_m"] = target_m
    run_stage(
        "subdivide", settings, inputs, out_dir,
        lambda: _subdivide(
            mesh_path, vis_path, posed or load_poses(poses_dir), conf, vconf, out_dir, target_m
        ),
    )
    return out_dir / MESH
