"""Evaluation against ground truth (the paper's metrics): geometric accuracy (mean distance
from the reconstructed vertices to the true surface) and completeness (mean distance from the
true vertices to the reconstructed surface), spectral RMSE per vertex against the true
reflectance at the closest true surface point (barycentric interpolation of the true per-vertex
spectra), and the error of the light offset."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import matplotlib
import numpy as np
import trimesh
from scipy.spatial import cKDTree

from core.errors import RigError
from core.lock import output_lock
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.raycast import RayCaster
from reconstruct.model.render import render_image
from reconstruct.outputs import export, plots
from reconstruct.outputs.relight import encode_srgb
from reconstruct.stages import publish

EVALUATION_FILE, RMSE_FILE, ERROR_MAP, ERROR_HIST = publish.EVALUATION


@dataclass
class Evaluation:
    accuracy_m: float
    completeness_m: float
    spectral_rmse: float  # mean over observed vertices of the per-vertex RMSE
    spectral_rmse_all: float  # mean over all vertices
    observed_vertices: int
    vertices: int
    light_offset_error_m: float | None = None
    light_offset_m: list[float] | None = None
    files: list[str] = field(default_factory=list)

    def table(self) -> list[tuple[str, str]]:
        rows = [
            ("accuracy (mean distance recon → truth)", f"{self.accuracy_m * 1e3:.3f} mm"),
            ("completeness (mean distance truth → recon)", f"{self.completeness_m * 1e3:.3f} mm"),
            (
                f"spectral RMSE ({self.observed_vertices} observed vertices)",
                f"{self.spectral_rmse:.4f}",
            ),
            (f"spectral RMSE (all {self.vertices} vertices)", f"{self.spectral_rmse_all:.4f}"),
        ]
        if self.light_offset_error_m is not None:
            rows.append(("light offset error", f"{self.light_offset_error_m * 1e3:.2f} mm"))
        return rows


def load_mesh(path: Path) -> trimesh.Trimesh:
    try:
        mesh = trimesh.load(path, process=False, force="mesh")
    except Exception as error:  # trimesh raises many types for unreadable files
        raise RigError(
            f"cannot read mesh {path}: {error}", "give a PLY/OBJ/STL triangle mesh"
        ) from error
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise RigError(f"{path} holds no triangle mesh", "give a PLY/OBJ/STL triangle mesh")
    return mesh


def surface_distance(
    points: np.ndarray, mesh: trimesh.Trimesh, candidates: int = 16, chunk: int = 50000
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance of each point to the surface, the closest points and their triangles.

    Exact point–triangle distances (``trimesh.triangles.closest_point``) to the ``candidates``
    triangles whose centroids are nearest (k-d tree): vectorised, and exact whenever the closest
    triangle is among them, which holds for meshes without long sliver triangles.
    """
    tris = np.asarray(mesh.triangles)
    tree = cKDTree(tris.mean(axis=1))
    k = min(candidates, len(tris))
    dist = np.empty(len(points))
    closest = np.empty((len(points), 3))
    tri = np.empty(len(points), dtype=np.int64)
    for lo in range(0, len(points), chunk):
        p = np.asarray(points[lo : lo + chunk], dtype=float)
        _, cand = tree.query(p, k=k)
        cand = np.asarray(cand).reshape(len(p), k)
        q = trimesh.triangles.closest_point(tris[cand.ravel()], np.repeat(p, k, axis=0))
        d = np.linalg.norm(q - np.repeat(p, k, axis=0), axis=1).reshape(len(p), k)
        best = np.argmin(d, axis=1)
        rows = np.arange(len(p))
        dist[lo : lo + len(p)] = d[rows, best]
        closest[lo : lo + len(p)] = q.reshape(len(p), k, 3)[rows, best]
        tri[lo : lo + len(p)] = cand[rows, best]
    return dist, closest, tri


def interpolate_at(
    mesh: trimesh.Trimesh, values: np.ndarray, points: np.ndarray, tri: np.ndarray
) -> np.ndarray:
    """Per-vertex ``values`` of ``mesh`` interpolated at surface points on triangles ``tri``."""
    corners = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[tri]]
    bary = trimesh.triangles.points_to_barycentric(corners, points)
    bary = np.clip(bary, 0.0, 1.0)
    bary /= bary.sum(axis=1, keepdims=True)
    return np.einsum("mk,mkl->ml", bary, values[np.asarray(mesh.faces)[tri]])


def error_map(
    path: Path, vertices: np.ndarray, faces: np.ndarray, errors: np.ndarray, vmax: float
) -> Path:
    """Two views of the mesh coloured by per-vertex error (viridis, 0..vmax), lit from the eye."""
    cmap = matplotlib.colormaps["viridis"]
    colours = cmap(np.clip(np.nan_to_num(errors) / max(vmax, 1e-12), 0.0, 1.0))[:, :3]
    centre = vertices.mean(axis=0)
    radius = float(np.max(np.linalg.norm(vertices - centre, axis=1)))
    caster = RayCaster(vertices, faces)
    intr = Intrinsics.pinhole(400, 400, 400 * 1.6)
    tiles = []
    for direction in ((1.0, 0.6, 0.5), (-1.0, -0.6, 0.3)):
        d = np.asarray(direction) / np.linalg.norm(direction)
        eye = centre + 3.5 * radius * d
        img, cover = render_image(
            vertices,
            faces,
            colours,
            intr,
            Pose.look_at(eye, centre),
            eye,
            np.eye(3) * (3.5 * radius) ** 2,
            caster=caster,
        )
        img = img + (1.0 - cover[..., None])
        tiles.append(encode_srgb(img))
    return plots.image(
        path, np.concatenate(tiles, axis=1), f"spectral RMSE per vertex (0 … {vmax:.3f})"
    )


def evaluate(
    recon: Path,
    gt_mesh: Path,
    gt_reflectance: Path,
    gt_light_offset: np.ndarray | None = None,
    out_dir: Path | None = None,
) -> Evaluation:
    """Compare a reconstruction (``recon`` folder or its ``reflectance.npz``) with the truth;
    the session written into stays locked (core.lock) meanwhile."""
    recon = Path(recon)
    out = Path(out_dir) if out_dir else (recon if recon.is_dir() else recon.parent)
    with output_lock(out, "rig evaluate"):
        return _evaluate(recon, gt_mesh, gt_reflectance, gt_light_offset, out)


def _evaluate(
    recon: Path,
    gt_mesh: Path,
    gt_reflectance: Path,
    gt_light_offset: np.ndarray | None,
    out: Path,
) -> Evaluation:
    npz_path = recon / export.REFLECTANCE_FILE if recon.is_dir() else recon
    data = export.read_reflectance_npz(npz_path)
    X = np.asarray(data["vertices"], dtype=float)
    faces = np.asarray(data["faces"], dtype=np.int64)
    refl = np.asarray(data["reflectance"], dtype=float)
    observed = np.asarray(data.get("observed", np.ones(len(X), bool)), dtype=bool)
    gt = load_mesh(Path(gt_mesh))
    try:
        gt_refl = np.load(gt_reflectance, allow_pickle=False)
    except (OSError, ValueError) as error:
        raise RigError(
            f"cannot read {gt_reflectance}: {error}", "give a .npy (N_gt, N_λ)"
        ) from error
    if gt_refl.shape != (len(gt.vertices), refl.shape[1]):
        raise RigError(
            f"{gt_reflectance} has shape {gt_refl.shape}, "
            f"expected ({len(gt.vertices)}, {refl.shape[1]})",
            "give one spectrum per vertex of the ground-truth mesh on the reconstruction's grid",
        )
    d_acc, closest, tri = surface_distance(X, gt)
    recon_mesh = trimesh.Trimesh(X, faces, process=False)
    d_comp, _, _ = surface_distance(np.asarray(gt.vertices, dtype=float), recon_mesh)
    truth = interpolate_at(gt, gt_refl, closest, tri)
    rmse = np.sqrt(np.mean((refl - truth) ** 2, axis=1))
    ev = Evaluation(
        accuracy_m=float(np.mean(d_acc)),
        completeness_m=float(np.mean(d_comp)),
        spectral_rmse=float(np.mean(rmse[observed])) if observed.any() else float("nan"),
        spectral_rmse_all=float(np.mean(rmse)),
        observed_vertices=int(observed.sum()),
        vertices=len(X),
    )
    report_path = (recon if recon.is_dir() else recon.parent) / export.REPORT_FILE
    if gt_light_offset is not None:
        if not report_path.is_file():
            raise RigError(f"{report_path} is missing", "it holds the estimated light offset")
        offset = json.loads(report_path.read_text())["light"].get("offset_m")
        if offset is None:
            raise RigError(
                f"{report_path} has free light positions, no offset to compare",
                "omit --gt-light-offset for a free-light reconstruction",
            )
        ev.light_offset_m = [float(v) for v in offset]
        ev.light_offset_error_m = float(
            np.linalg.norm(np.asarray(offset) - np.asarray(gt_light_offset))
        )
    vmax = float(np.percentile(rmse[observed], 95)) if observed.any() else float(rmse.max())
    files = [
        error_map(out / ERROR_MAP, X, faces, np.where(observed, rmse, np.nan), vmax),
        plots.error_histogram(
            out / ERROR_HIST, rmse[observed], "spectral RMSE per vertex"
        ),
    ]
    ev.files = [str(f) for f in files]
    np.save(out / RMSE_FILE, rmse)
    export.write_report(out / EVALUATION_FILE, asdict(ev))
    return ev
