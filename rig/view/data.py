"""What the viewer shows, gathered from a reconstruction folder (and its session's ground truth
when the session came from the sim rig or the external-renderer benchmark)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from core.session import RECON_DIR
from reconstruct.model.camera import read_colmap_text
from reconstruct.outputs.evaluate import interpolate_at, load_mesh
from reconstruct.outputs.export import REFLECTANCE_FILE, read_reflectance_npz
from reconstruct.outputs.result import recon_dir_of


@dataclass
class ViewData:
    """Per-vertex spectra on the grid ``wavelengths_nm`` and the scene around them (metres)."""

    name: str
    vertices: np.ndarray  # (N, 3)
    faces: np.ndarray  # (F, 3)
    wavelengths_nm: np.ndarray  # (L,)
    reflectance: np.ndarray  # (N, L)
    observed: np.ndarray  # (N,) bool
    initial: np.ndarray | None  # (N, L) the 2-D estimate the solve started from
    truth: np.ndarray | None  # (N, L) ground truth at the vertices
    basis: np.ndarray | None  # (L, K) the reflectance basis of the solve
    cameras: np.ndarray  # (M, 3) camera centres
    lights: np.ndarray  # (K, 3) estimated light positions


def load_view_data(path: Path) -> ViewData:
    recon = recon_dir_of(path)
    arrays = read_reflectance_npz(recon / REFLECTANCE_FILE)
    vertices = arrays["vertices"].astype(float)
    n = len(vertices)
    report_path = recon / "report.json"
    report = json.loads(report_path.read_text()) if report_path.is_file() else {}
    lights = np.asarray((report.get("light") or {}).get("positions_m") or np.zeros((0, 3)), float)
    return ViewData(
        name=recon.parent.name if recon.name == RECON_DIR else recon.name,
        vertices=vertices,
        faces=arrays["faces"].astype(np.int64),
        wavelengths_nm=arrays["wavelengths_nm"].astype(float),
        reflectance=arrays["reflectance"].astype(float),
        observed=arrays.get("observed", np.ones(n, bool)).astype(bool),
        initial=arrays.get("initial_reflectance"),
        basis=arrays.get("basis"),
        truth=_truth_at(recon.parent / "ground_truth", vertices, arrays["wavelengths_nm"]),
        cameras=_camera_centres(recon / "poses"),
        lights=lights.reshape(-1, 3),
    )


def _camera_centres(poses_dir: Path) -> np.ndarray:
    if not (poses_dir / "images.txt").is_file():
        return np.zeros((0, 3))
    _, images = read_colmap_text(poses_dir)
    return np.array([pose.center for _, _, pose in images.values()]).reshape(-1, 3)


def _truth_at(gt: Path, vertices: np.ndarray, wavelengths: np.ndarray) -> np.ndarray | None:
    """The ground-truth reflectance at the reconstruction's vertices (closest true surface
    point), when the session keeps one (sim and external-renderer sessions)."""
    mesh_file, refl_file = gt / "mesh.ply", gt / "reflectance.npy"
    if not (mesh_file.is_file() and refl_file.is_file()):
        return None
    mesh = load_mesh(mesh_file)
    values = np.load(refl_file)
    if values.shape != (len(mesh.vertices), len(wavelengths)):
        return None
    points, _, tri = trimesh.proximity.closest_point(mesh, vertices)
    return interpolate_at(mesh, values, points, tri)
