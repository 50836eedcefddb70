"""Scenes for the external-renderer benchmark, from real measured data only.

A scanned mesh (``meshes/``) scaled to a given size, segmented into patches by a 3-D Voronoi
of seed vertices (uneven cell sizes: some patches are big and untextured) and painted with the
24 ColorChecker reflectances; measured lamp SPDs (``spd/``) as the illuminations; a measured
camera sensitivity (``camera_ssf/``). Everything is resampled onto the project's spectral grid
so the exact spectral composition ``Σ_k shading_k · Cᵀ diag(L) ρ_k`` happens on the same grid
the reconstruction works on.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from calibration.defaults import colorchecker_reflectances
from calibration.grid import DEFAULT_GRID
from calibration.spectra import resample
from core.errors import RigError
from drivers.sim.scene import Scene

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("SPECTRAL_RIG_SHARED", REPO.parent / "shared")) / "data"
LAMPS_CSV = "spd/photobiologylamps_lamps_380_780_1nm.csv"
ELGATO_CSV = "spd/elgato_key_light_mini_cct_380_780_1nm.csv"
CAMSPEC_TXT = "camera_ssf/camspec_database_27.txt"


def data_file(data: Path, rel: str) -> Path:
    """A file of the shared data folder, or one clear error naming it."""
    path = Path(data) / rel
    if not path.is_file():
        raise RigError(
            f"benchmark data file {path} is missing",
            "point --data at the shared data folder (its README lists the files)",
        )
    return path


def load_mesh(path: Path, size_m: float, max_edge_m: float = 0.0015) -> trimesh.Trimesh:
    """The mesh turned z-up (the OBJ files are y-up), its longest side scaled to ``size_m``
    and its bounding-box centre at the origin; Loop-subdivided until its mean edge is at
    most ``max_edge_m``.

    Why subdivide: Mitsuba shades a mesh with interpolated vertex normals, so a coarse
    model (spot's and cow's 4–6 mm facets, 8–17° between neighbours) would be rendered as
    a smooth object while its truth stays faceted: shading and disparity would disagree by
    ~0.1–0.15 mm (a facet's sagitta), an object no camera can see. Loop's limit surface is
    smooth, so after two steps (~1 mm facets, 2–4°) the surface scored is the one shaded."""
    mesh = trimesh.load(path, process=True, force="mesh")
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise RigError(f"{path} holds no triangle mesh", "give an OBJ/PLY triangle mesh")
    v = np.asarray(mesh.vertices, dtype=float)
    v = np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1)  # y-up -> z-up
    faces = np.asarray(mesh.faces)
    for _ in range(4):
        scaled = trimesh.Trimesh(_fit(v, size_m), faces, process=False)
        if float(scaled.edges_unique_length.mean()) <= max_edge_m:
            break
        v, faces = trimesh.remesh.subdivide_loop(v, faces, iterations=1)
    return trimesh.Trimesh(_fit(v, size_m), faces, process=False)


def _fit(v: np.ndarray, size_m: float) -> np.ndarray:
    """Vertices scaled so the longest bounding-box side is ``size_m``, centred at 0."""
    lo, hi = v.min(axis=0), v.max(axis=0)
    return (v - (lo + hi) / 2) * (size_m / float(np.max(hi - lo)))


def voronoi_patches(vertices: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Patch index per vertex: the nearest of ``n`` random seed vertices (a 3-D Voronoi, so
    cells differ in size and some are big, untextured regions)."""
    rng = np.random.default_rng(seed)
    seeds = vertices[rng.choice(len(vertices), size=n, replace=False)]
    d2 = (
        np.sum(vertices**2, axis=1)[:, None]
        - 2.0 * vertices @ seeds.T
        + np.sum(seeds**2, axis=1)[None, :]
    )
    return np.asarray(np.argmin(d2, axis=1), dtype=np.int64)


def painted_scene(name: str, mesh: trimesh.Trimesh, n_patches: int, seed: int) -> Scene:
    """The mesh painted with ColorChecker reflectances, one per Voronoi patch (patch ``k``
    gets chart patch ``k mod 24``)."""
    vertices = np.asarray(mesh.vertices, dtype=float)
    cell = voronoi_patches(vertices, n_patches, seed)
    _, chart = colorchecker_reflectances()
    patch = cell % len(chart)
    return Scene(
        name=name,
        vertices=vertices,
        faces=np.asarray(mesh.faces, dtype=np.int64),
        reflectance=chart[patch],
        wavelengths=DEFAULT_GRID.wavelengths,
        patch=patch,
    )


def _csv_spectrum(path: Path, column: str) -> np.ndarray:
    header = path.open().readline().strip().split(",")
    if column not in header:
        raise RigError(
            f"{path} has no lamp column {column!r}",
            f"use one of its columns, e.g. {', '.join(header[1:4])}",
        )
    table = np.loadtxt(path, delimiter=",", skiprows=1, usecols=(0, header.index(column)))
    return resample(table[:, 0], table[:, 1], DEFAULT_GRID, source=f"{path} ({column})")


def lamp_spd(data: Path, name: str) -> np.ndarray:
    """A measured lamp SPD on the grid: a column of the photobiologyLamps table, or
    ``elgato:COLUMN`` of the tunable Elgato panel's table. Scaled to unit mean."""
    if name.startswith("elgato:"):
        spd = _csv_spectrum(data_file(data, ELGATO_CSV), name.split(":", 1)[1])
    else:
        spd = _csv_spectrum(data_file(data, LAMPS_CSV), name)
    return spd / float(np.mean(spd))


def camera_ssf(data: Path, name: str) -> np.ndarray:
    """A measured camera sensitivity (N_λ, 3) from the camspec database, peak 1."""
    path = data_file(data, CAMSPEC_TXT)
    lines = [ln.strip() for ln in path.read_text().splitlines() if ln.strip()]
    lines = [ln for ln in lines if not ln.startswith("#")]
    names = lines[::4]
    if name not in names:
        raise RigError(f"{path} has no camera {name!r}", f"use one of {', '.join(names[:5])}...")
    i = 4 * names.index(name)
    rgb = np.array([[float(x) for x in lines[i + c].split()] for c in (1, 2, 3)]).T
    wl = np.arange(400.0, 721.0, 10.0)
    ssf = resample(wl, rgb, DEFAULT_GRID, source=f"{path} ({name})")
    return ssf / float(ssf.max())


@dataclass(frozen=True)
class SceneSpec:
    """One benchmark scene: which mesh, lamps (illumination name -> lamp), camera and path."""

    name: str
    mesh: str  # file name under meshes/
    lamps: dict[str, str]
    camera: str
    distance_factors: tuple[float, ...]  # (1.0,): one ring at one distance; else stepped
    elevations_deg: tuple[float, ...]
    ambient_lamp: str = "Philips.FT.TLD.36W.965"
    seed: int = 0
