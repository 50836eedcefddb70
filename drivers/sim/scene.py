"""Virtual scenes: a mesh (metres, world z up, object at the origin) with a spectral reflectance
per vertex, painted with the 24 ColorChecker reflectances.

Built-in scenes (all seeded, deterministic):

* ``blob`` (default): a sphere of ~7 cm radius deformed by low-frequency noise plus several
  octaves of fine bumps (~1 mm), 164k vertices — fine detail for shading to recover.
* ``torus``: a bumpy torus (6 cm ring, 2.5 cm tube); concavities and self-shadowing, for
  evaluation on a second shape.
* ``chart``: a flat 6x4 ColorChecker card in the z = 0 plane facing +z (2-D checks).
* ``card``: a large diffuse white card (80 cm square) in the z = 0 plane facing +z, with a
  faint paper texture (±3 %): the flat-field target (:mod:`drivers.sim.white_card`).

Ground truth is saved as ``mesh.ply`` + ``reflectance.npy`` (V, N_λ) + ``scene.yaml``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
import yaml

from calibration.defaults import colorchecker_reflectances
from calibration.grid import DEFAULT_GRID, SpectralGrid
from core.errors import RigError
from core.files import atomic_output, write_bytes_atomically

SCENES = ("blob", "torus", "chart", "card")
_CHART_BORDER = 0.03  # reflectance of the card between patches (near black)
CARD_SIDE_M = 0.8
CARD_WHITE = 0.9
CARD_TEXTURE = 0.03  # RMS of the white card's texture, relative


@dataclass(frozen=True)
class Scene:
    """A mesh with one reflectance spectrum per vertex and the ColorChecker patch it came from
    (-1 = not a patch)."""

    name: str
    vertices: np.ndarray  # (V, 3) metres
    faces: np.ndarray  # (F, 3)
    reflectance: np.ndarray  # (V, N_λ)
    wavelengths: np.ndarray  # (N_λ,)
    patch: np.ndarray  # (V,) int

    def save(self, folder: Path) -> None:
        """Write ``mesh.ply``, ``reflectance.npy``, ``patch.npy`` and ``scene.yaml``."""
        folder.mkdir(parents=True, exist_ok=True)
        mesh = trimesh.Trimesh(self.vertices, self.faces, process=False)
        with atomic_output(folder / "mesh.ply") as tmp:
            mesh.export(tmp, encoding="binary")
        with atomic_output(folder / "reflectance.npy") as tmp:
            np.save(tmp, self.reflectance.astype(np.float32))
        with atomic_output(folder / "patch.npy") as tmp:
            np.save(tmp, self.patch.astype(np.int16))
        meta = {
            "name": self.name,
            "units": "metres",
            "vertices": int(len(self.vertices)),
            "wavelengths_nm": [float(w) for w in self.wavelengths],
            "reflectance": "reflectance.npy: (vertices, wavelengths) float32",
            "patch": "patch.npy: ColorChecker 24 patch index per vertex (-1 = none)",
            "patch_names": colorchecker_reflectances()[0],
        }
        text = yaml.safe_dump(meta, sort_keys=False)
        write_bytes_atomically(folder / "scene.yaml", text.encode())

    @classmethod
    def load(cls, folder: Path) -> Scene:
        """Read a scene written by :meth:`save`."""
        for name in ("mesh.ply", "reflectance.npy", "scene.yaml"):
            if not (folder / name).is_file():
                raise RigError(
                    f"ground truth {folder / name} is missing",
                    "write it with SimRig.write_ground_truth or Scene.save",
                )
        mesh: Any = trimesh.load(folder / "mesh.ply", process=False, force="mesh")
        meta = yaml.safe_load((folder / "scene.yaml").read_text())
        refl = np.load(folder / "reflectance.npy").astype(float)
        patch_file = folder / "patch.npy"
        v = np.asarray(mesh.vertices, dtype=float)
        patch = np.load(patch_file).astype(int) if patch_file.is_file() else np.full(len(v), -1)
        if refl.shape[0] != len(v):
            raise RigError(
                f"{folder / 'reflectance.npy'} has {refl.shape[0]} rows, "
                f"mesh.ply has {len(v)} vertices",
                "write mesh and reflectance together (Scene.save)",
            )
        return cls(
            str(meta["name"]),
            v,
            np.asarray(mesh.faces, dtype=np.int64),
            refl,
            np.asarray(meta["wavelengths_nm"], dtype=float),
            patch,
        )


def _fractal(points: np.ndarray, rng: np.random.Generator, freqs: list[float]) -> np.ndarray:
    """Smooth noise: per octave, a sum of 24 random plane waves of spatial frequency ``f``
    (radians per unit), amplitude ∝ 1/f, normalised to unit RMS overall."""
    out = np.zeros(len(points))
    for f in freqs:
        u = rng.normal(size=(3, 24))
        u /= np.linalg.norm(u, axis=0)
        phase = rng.uniform(0, 2 * np.pi, 24)
        out += np.sin(f * (points @ u) + phase).sum(axis=1) / f
    return out / max(float(np.sqrt(np.mean(out**2))), 1e-12)


def _paint(points: np.ndarray, n_regions: int, rng: np.random.Generator) -> np.ndarray:
    """ColorChecker patch index per point: Voronoi regions around farthest-point-sampled seeds,
    each region one patch (all 24 used before any repeats)."""
    seeds = [int(rng.integers(len(points)))]
    dist = np.linalg.norm(points - points[seeds[0]], axis=1)
    for _ in range(n_regions - 1):
        seeds.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(points - points[seeds[-1]], axis=1))
    d2 = ((points[:, None, :] - points[seeds][None, :, :]) ** 2).sum(axis=2)
    region = np.argmin(d2, axis=1)
    colours = np.concatenate([rng.permutation(24) for _ in range(-(-n_regions // 24))])
    return colours[region]


def _blob(rng: np.random.Generator, subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    d = np.asarray(sphere.vertices, dtype=float)
    shape = _fractal(d, rng, [1.5, 2.5])
    bumps = _fractal(d, rng, [12.0, 20.0, 32.0, 48.0])
    radius = 0.07 * (1.0 + 0.12 * shape) + 0.0012 * bumps
    return d * radius[:, None], np.asarray(sphere.faces, dtype=np.int64)


def _torus(rng: np.random.Generator, subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    # whole counts below subdivisions 5 too (2 ** -1 was a float: an unusable mesh)
    n_major = max(12, round(100 * 2.0 ** (subdivisions - 5)))
    n_minor = max(6, round(40 * 2.0 ** (subdivisions - 5)))
    R, r = 0.06, 0.025
    theta = 2 * np.pi * np.arange(n_major) / n_major
    phi = 2 * np.pi * np.arange(n_minor) / n_minor
    T, P = (grid.ravel() for grid in np.meshgrid(theta, phi, indexing="ij"))
    ring = np.stack([np.cos(T), np.sin(T), np.zeros_like(T)], axis=1)
    normal = np.cos(P)[:, None] * ring + np.sin(P)[:, None] * np.array([0.0, 0.0, 1.0])
    base = R * ring + r * normal
    bumps = _fractal(base / R, rng, [10.0, 18.0, 30.0, 45.0])
    lump = _fractal(base / R, rng, [2.0])
    v = base + (r * 0.15 * lump + 0.001 * bumps)[:, None] * normal
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a = i * n_minor + j
    b = ((i + 1) % n_major) * n_minor + j
    c = ((i + 1) % n_major) * n_minor + (j + 1) % n_minor
    d = i * n_minor + (j + 1) % n_minor
    f = np.concatenate(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    )
    return v, f


def _chart(resolution_m: float = 0.001) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 6x4 card of 20 mm patches with 4 mm borders, in z = 0 facing +z, centred at 0."""
    pitch, size = 0.024, 0.020
    w, h = 6 * pitch + 0.004, 4 * pitch + 0.004
    nx, ny = int(round(w / resolution_m)), int(round(h / resolution_m))
    xs = np.linspace(-w / 2, w / 2, nx + 1)
    ys = np.linspace(-h / 2, h / 2, ny + 1)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    v = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = i * (ny + 1) + j
    b, c, d = a + (ny + 1), a + (ny + 2), a + 1
    f = np.concatenate(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    )
    # Patch order as on the card: row 0 (top, +y) holds patches 0..5 left to right.
    col = np.floor((v[:, 0] + w / 2 - 0.004) / pitch).astype(int)
    row = np.floor((h / 2 - v[:, 1] - 0.004) / pitch).astype(int)
    local_x = (v[:, 0] + w / 2 - 0.004) - col * pitch
    local_y = (h / 2 - v[:, 1] - 0.004) - row * pitch
    inside = (
        (col >= 0)
        & (col < 6)
        & (row >= 0)
        & (row < 4)
        & (local_x >= 0)
        & (local_x <= size)
        & (local_y >= 0)
        & (local_y <= size)
    )
    patch = np.where(inside, row * 6 + col, -1)
    return v, f.astype(np.int64), patch


def _card(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The white card: a square grid of 4 mm cells and its texture (reflectance factor)."""
    n = int(round(CARD_SIDE_M / 0.004))
    xs = np.linspace(-CARD_SIDE_M / 2, CARD_SIDE_M / 2, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    v = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = i * (n + 1) + j
    b, c, d = a + (n + 1), a + (n + 2), a + 1
    f = np.concatenate(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    )
    texture = 1.0 + CARD_TEXTURE * _fractal(v, rng, [150.0, 400.0])
    return v, f.astype(np.int64), texture


def make_scene(
    name: str = "blob", seed: int = 0, subdivisions: int = 7, grid: SpectralGrid = DEFAULT_GRID
) -> Scene:
    """A built-in scene by name (see module docstring), deterministic for ``seed``.

    ``subdivisions`` sets the mesh density (7: ~164k vertices for ``blob``; lower is faster).
    """
    rng = np.random.default_rng([seed, SCENES.index(name) if name in SCENES else 99])
    if name == "blob":
        v, f = _blob(rng, subdivisions)
        patch = _paint(v, 48, rng)
    elif name == "torus":
        v, f = _torus(rng, subdivisions)
        patch = _paint(v, 48, rng)
    elif name == "chart":
        v, f, patch = _chart()
    elif name == "card":
        v, f, texture = _card(rng)
        refl = np.clip(CARD_WHITE * texture, 0.0, 1.0)[:, None] * np.ones(grid.size)
        return Scene(name, v, f, refl, grid.wavelengths, np.full(len(v), -1))
    else:
        raise RigError(f"unknown sim scene {name!r}", f"use one of {', '.join(SCENES)}")
    _, cc = colorchecker_reflectances(grid)
    refl = np.where(patch[:, None] >= 0, cc[np.maximum(patch, 0)], _CHART_BORDER)
    return Scene(name, v, f, refl, grid.wavelengths, patch)
