"""Evaluation against ground truth (the paper's metrics): geometric accuracy (mean distance
from the reconstructed vertices to the true surface) and completeness (mean distance from the
true vertices to the reconstructed surface), spectral RMSE per vertex against the true
reflectance at the closest true surface point (barycentric interpolation of the true per-vertex
spectra), CIEDE2000 under D65, A and any illuminant asked for (per vertex, and per patch where
the truth labels patches: ``patch.npy`` beside the true reflectance), and the error of the
light offset."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
import trimesh
from scipy.spatial import cKDTree

from calibration.basis import default_basis
from calibration.colour_difference import (
    DEFAULT_ILLUMINANTS,
    ColourReport,
    Illuminant,
    colour_report,
    illuminant,
)
from calibration.defaults import colorchecker_reflectances
from calibration.estimation import noise_free_estimate
from core.errors import RigError
from core.files import atomic_output
from core.lock import output_lock
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.raycast import RayCaster
from reconstruct.model.render import render_image
from reconstruct.outputs import export, plots
from reconstruct.outputs.relight import encode_srgb
from reconstruct.stages import publish

EVALUATION_FILE, RMSE_FILE, ERROR_MAP, ERROR_HIST = publish.EVALUATION
PATCH_FILE = "patch.npy"  # beside the true reflectance: patch label per true vertex (-1 = none)
# A patch counts in the per-patch mean when the reconstruction saw at least a spectrometer's
# aperture of its interior (3 mm, the small-area view of common 45/0 instruments): a patch
# seen only along its border with a neighbour has a median of mixed paint, not a reading.
APERTURE_M = 3e-3


@dataclass
class Evaluation:
    accuracy_m: float
    completeness_m: float
    spectral_rmse: float  # mean over observed vertices of the per-vertex RMSE
    spectral_rmse_all: float  # mean over all vertices
    observed_vertices: int
    vertices: int
    # reflectance samples (vertex, wavelength) below 0 or above 1: physically impossible values
    outside_unit_range: int = 0
    reflectance_range: tuple[float, float] = (0.0, 1.0)
    light_offset_error_m: float | None = None
    light_offset_m: list[float] | None = None
    colour: list[dict[str, Any]] = field(default_factory=list)  # ColourReport.as_dict per light
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
            (
                "reflectance samples outside [0, 1] (min / max)",
                f"{self.outside_unit_range} ({self.reflectance_range[0]:.3f} / "
                f"{self.reflectance_range[1]:.3f})",
            ),
        ]
        rows += colour_rows(self.colour)
        if self.light_offset_error_m is not None:
            rows.append(("light offset error", f"{self.light_offset_error_m * 1e3:.2f} mm"))
        return rows


def colour_rows(reports: Sequence[dict[str, Any]]) -> list[tuple[str, str]]:
    """Table rows of :meth:`ColourReport.as_dict` entries: ΔE00 per vertex and per patch."""
    rows = []
    for r in reports:
        v = r["per_vertex"]
        rows.append((f"ΔE00 {r['illuminant']} per vertex mean / median / p90",
                     f"{v['mean']:.2f} / {v['median']:.2f} / {v['p90']:.2f}"))  # fmt: skip
        if r["patches"]:
            counted = f"{r['patches_measured']} of {len(r['patches'])} measured"
            mean, top = r["patch_mean"], r["patch_max"]
            value = "-" if mean is None else f"{mean:.2f} / {top:.2f}"
            rows.append((f"ΔE00 {r['illuminant']} per patch ({counted}) mean / max", value))
    return rows


def patch_table(reports: Sequence[dict[str, Any]]) -> tuple[list[str], list[list[str]]]:
    """Columns and rows of the per-patch table: one ΔE00 column per illuminant, the RMSE, and
    whether the patch is measured (counted in the mean and max)."""
    if not reports or not reports[0]["patches"]:
        return [], []
    columns = [
        "patch", "vertices", *(f"ΔE00 {r['illuminant']}" for r in reports), "RMSE", "measured"
    ]  # fmt: skip
    rows = []
    for k, p in enumerate(reports[0]["patches"]):
        des = [f"{r['patches'][k]['delta_e00']:.2f}" for r in reports]
        measured = "yes" if p["measured"] else "no: too little seen"
        rows.append([p["name"], str(p["vertices"]), *des, f"{p['rmse']:.4f}", measured])
    return columns, rows


def truth_patches(gt_reflectance: Path, n_true: int) -> np.ndarray | None:
    """Patch label per true vertex from ``patch.npy`` beside the true reflectance (None when
    the truth has no patches)."""
    path = Path(gt_reflectance).parent / PATCH_FILE
    if not path.is_file():
        return None
    labels = np.load(path, allow_pickle=False).astype(int)
    if labels.shape != (n_true,):
        raise RigError(
            f"{path} has shape {labels.shape}, expected ({n_true},)",
            "give one patch label per true vertex (-1 = none), or remove the file",
        )
    return labels if (labels >= 0).any() else None


def colour_reports(
    estimate: np.ndarray,
    truth: np.ndarray,
    observed: np.ndarray,
    patch: np.ndarray | None,
    lights: Sequence[Illuminant],
    unmeasured: Sequence[int] = (),
) -> list[ColourReport]:
    """ΔE00 per illuminant over the observed vertices (ColorChecker names for 24 patches), the
    patches in ``unmeasured`` left out of the patch mean and max."""
    names = colorchecker_reflectances()[0]
    use = names if patch is not None and patch.max() < len(names) else None
    return [
        colour_report(estimate, truth, light, observed, patch, use, unmeasured)
        for light in lights
    ]


def unmeasured_patches(
    vertices: np.ndarray, faces: np.ndarray, patch: np.ndarray, observed: np.ndarray
) -> list[int]:
    """Patch labels whose interior the reconstruction saw less of than a spectrometer's
    aperture (a disc of diameter :data:`APERTURE_M`). A patch's interior is its observed
    vertices whose neighbours are all observed and in the same patch, each weighing a third of
    the area of its faces."""
    labels = np.asarray(patch, dtype=int)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    border = ~np.asarray(observed, dtype=bool)
    crossing = (labels[edges[:, 0]] != labels[edges[:, 1]]) | border[edges].any(axis=1)
    border[edges[crossing].ravel()] = True
    area = np.zeros(len(vertices))
    np.add.at(area, faces.ravel(), np.repeat(trimesh.triangles.area(vertices[faces]) / 3.0, 3))
    inside = ~border & (labels >= 0)
    seen = np.bincount(labels[inside], weights=area[inside], minlength=labels.max() + 1)
    aperture = np.pi * (APERTURE_M / 2) ** 2
    return [int(k) for k in np.unique(labels[labels >= 0]) if seen[k] < aperture]


def information_floor(
    gt_reflectance: Path, responses: np.ndarray, illuminants: Sequence[Illuminant] | None = None
) -> dict[str, Any]:
    """The 2-D estimator given the true shading: each true reflectance estimated by
    ``calibration.estimation`` from its noise-free responses (K, 3, N_λ) of the session's
    illuminations and camera — the best the data allows — scored by RMSE and ΔE00 (per vertex
    over all true vertices, per patch where ``patch.npy`` labels them)."""
    truth = np.load(gt_reflectance, allow_pickle=False)
    estimate = noise_free_estimate(truth, responses, default_basis())
    rmse = np.sqrt(np.mean((estimate - truth) ** 2, axis=1))
    patch = truth_patches(Path(gt_reflectance), len(truth))
    lights = illuminants or [illuminant(n) for n in DEFAULT_ILLUMINANTS]
    colour = colour_reports(estimate, truth, np.ones(len(truth), bool), patch, lights)
    return {
        "rmse_mean": float(rmse.mean()),
        "rmse_median": float(np.median(rmse)),
        "colour": [c.as_dict() for c in colour],
    }


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
    """Per-vertex ``values`` of ``mesh`` interpolated at surface points on triangles ``tri``;
    on a zero-area triangle (scans have a few) the nearest corner's value."""
    corners = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[tri]]
    with np.errstate(divide="ignore", invalid="ignore"):
        bary = trimesh.triangles.points_to_barycentric(corners, points)
    degenerate = ~np.all(np.isfinite(bary), axis=1)
    if degenerate.any():
        gap = np.linalg.norm(corners[degenerate] - points[degenerate, None, :], axis=2)
        bary[degenerate] = np.eye(3)[np.argmin(gap, axis=1)]
    bary = np.clip(bary, 0.0, 1.0)
    bary /= bary.sum(axis=1, keepdims=True)
    return np.einsum("mk,mkl->ml", bary, values[np.asarray(mesh.faces)[tri]])


def nearest_corner(mesh: trimesh.Trimesh, points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Index of the corner of triangle ``tri`` nearest each surface point (its label wins)."""
    corners = np.asarray(mesh.faces)[tri]
    d = np.linalg.norm(np.asarray(mesh.vertices)[corners] - points[:, None, :], axis=2)
    return corners[np.arange(len(points)), np.argmin(d, axis=1)]


def truth_at(
    points: np.ndarray, gt: trimesh.Trimesh, gt_reflectance: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each reconstructed point: its distance to the true surface, the true reflectance at
    the closest surface point, and the true vertex nearest that point (to look up a per-vertex
    label such as the patch)."""
    distance, closest, tri = surface_distance(points, gt)
    reflectance = interpolate_at(gt, gt_reflectance, closest, tri)
    return distance, reflectance, nearest_corner(gt, closest, tri)


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
    illuminants: Sequence[Illuminant] | None = None,
) -> Evaluation:
    """Compare a reconstruction (``recon`` folder or its ``reflectance.npz``) with the truth;
    ΔE00 under ``illuminants`` (default D65 and A); the session written into stays locked
    (core.lock) meanwhile."""
    recon = Path(recon)
    out = Path(out_dir) if out_dir else (recon if recon.is_dir() else recon.parent)
    with output_lock(out, "rig evaluate"):
        return _evaluate(recon, gt_mesh, gt_reflectance, gt_light_offset, out, illuminants)


def _evaluate(
    recon: Path,
    gt_mesh: Path,
    gt_reflectance: Path,
    gt_light_offset: np.ndarray | None,
    out: Path,
    illuminants: Sequence[Illuminant] | None,
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
    bad = np.unique(np.nonzero(~np.isfinite(gt_refl))[0])
    if bad.size:  # a NaN would make every score NaN and still exit 0
        raise RigError(
            f"{gt_reflectance}: {bad.size} of {len(gt_refl)} true spectra hold NaN or inf "
            f"(first: vertex {bad[0]})",
            "give a finite reflectance for every vertex of the ground-truth mesh",
        )
    gt_patch = truth_patches(Path(gt_reflectance), len(gt.vertices))
    d_acc, truth, corner = truth_at(X, gt, gt_refl)
    patch = None if gt_patch is None else gt_patch[corner]
    recon_mesh = trimesh.Trimesh(X, faces, process=False)
    d_comp, _, _ = surface_distance(np.asarray(gt.vertices, dtype=float), recon_mesh)
    rmse = np.sqrt(np.mean((refl - truth) ** 2, axis=1))
    lights = illuminants or [illuminant(n) for n in DEFAULT_ILLUMINANTS]
    unmeasured = [] if patch is None else unmeasured_patches(X, faces, patch, observed)
    colour = colour_reports(refl, truth, observed, patch, lights, unmeasured)
    ev = Evaluation(
        accuracy_m=float(np.mean(d_acc)),
        completeness_m=float(np.mean(d_comp)),
        spectral_rmse=float(np.mean(rmse[observed])) if observed.any() else float("nan"),
        spectral_rmse_all=float(np.mean(rmse)),
        observed_vertices=int(observed.sum()),
        vertices=len(X),
        outside_unit_range=int(np.count_nonzero((refl < 0) | (refl > 1))),
        reflectance_range=(float(refl.min()), float(refl.max())),
        colour=[c.as_dict() for c in colour],
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
    with atomic_output(out / RMSE_FILE) as tmp:
        np.save(tmp, rmse)
    export.write_report(out / EVALUATION_FILE, asdict(ev))
    return ev
