"""One reader for what `rig reconstruct` (or `rig demo`) leaves behind.

>>> from reconstruct.outputs.result import load_result
>>> result = load_result("rig-demo")            # the demo's folder, a session or its recon/
>>> result.mesh                                  # trimesh.Trimesh, metres
>>> result.reflectance.shape                     # (N, 31): 400-700 nm in 10 nm steps
>>> result.spectra[550]                          # colour.MultiSpectralDistributions, one per vertex
>>> result.reflectance_std, result.position_std_m  # uncertainty (NaN where not estimated)
>>> result.reflectance_band                      # (low, high): 95 % band inside [0, 1]
>>> result.report["light"]["offset_m"]
>>> result.paths.mesh                            # recon/mesh.ply

The arrays come from ``reflectance.npz`` (full precision); ``mesh.vertex_attributes`` holds
every per-vertex property of ``mesh.ply`` (``red``, ``refl_400`` … ``refl_700``,
``refl_std_*``, ``position_std_m``), which trimesh's own PLY loader keeps only in
``metadata['_ply_raw']``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import colour
import numpy as np
import trimesh

from core.errors import RigError
from core.session import RECON_DIR, find_session
from reconstruct.outputs.export import (
    MESH_FILE,
    REFLECTANCE_FILE,
    REPORT_FILE,
    read_reflectance_npz,
)

# PLY vertex properties trimesh already maps to vertices and normals
_GEOMETRY = ("x", "y", "z", "nx", "ny", "nz")


@dataclass(frozen=True)
class ResultPaths:
    recon_dir: Path
    mesh: Path
    reflectance: Path
    report: Path


@dataclass(frozen=True)
class ReconstructionResult:
    """A reconstruction: mesh, per-vertex spectra on ``wavelengths_nm``, uncertainty, report."""

    mesh: trimesh.Trimesh
    wavelengths_nm: np.ndarray  # (L,)
    reflectance: np.ndarray  # (N, L)
    reflectance_std: np.ndarray | None  # (N, L), NaN where not estimated
    position_std_m: np.ndarray | None  # (N,), along the normal
    # (low, high) (N, L) each: the 95 % band, inside the physical range; NaN where not estimated
    reflectance_band: tuple[np.ndarray, np.ndarray] | None
    observed: np.ndarray  # (N,) bool: seen by a camera (else filled from neighbours)
    report: dict[str, Any]
    paths: ResultPaths

    @cached_property
    def spectra(self) -> colour.MultiSpectralDistributions:
        """The per-vertex reflectance as one colour-science object (signal ``k``: vertex k);
        built on first use, as it takes seconds for tens of thousands of vertices."""
        return colour.MultiSpectralDistributions(
            self.reflectance.T, self.wavelengths_nm, name="reflectance per vertex"
        )


def recon_dir_of(path: Path | str) -> Path:
    """The folder holding ``reflectance.npz``: ``path`` itself, its ``recon/``, or the
    ``session/recon/`` of a demo's output folder."""
    path = Path(path)
    for candidate in (path, path / RECON_DIR, find_session(path) / RECON_DIR):
        if (candidate / REFLECTANCE_FILE).is_file():
            return candidate
    raise RigError(
        f"{path} holds no {REFLECTANCE_FILE} (nor does {path / RECON_DIR})",
        f"run `rig reconstruct {find_session(path)}` first, or give its recon/ folder",
    )


def load_result(path: Path | str) -> ReconstructionResult:
    """The reconstruction at ``path``: a session, its ``recon/`` folder or `rig demo`'s
    output folder (RigError naming what is missing)."""
    recon = recon_dir_of(path)
    paths = ResultPaths(
        recon, recon / MESH_FILE, recon / REFLECTANCE_FILE, recon / REPORT_FILE
    )
    arrays = read_reflectance_npz(paths.reflectance)
    n = len(arrays["vertices"])
    report = json.loads(paths.report.read_text()) if paths.report.is_file() else {}
    return ReconstructionResult(
        mesh=_mesh(paths.mesh, arrays),
        wavelengths_nm=arrays["wavelengths_nm"].astype(float),
        reflectance=arrays["reflectance"].astype(float),
        reflectance_std=arrays.get("reflectance_std"),
        position_std_m=arrays.get("position_std_m"),
        reflectance_band=(
            (arrays["reflectance_low"], arrays["reflectance_high"])
            if "reflectance_low" in arrays and "reflectance_high" in arrays
            else None
        ),
        observed=arrays.get("observed", np.ones(n, bool)).astype(bool),
        report=report,
        paths=paths,
    )


def _mesh(ply: Path, arrays: dict[str, np.ndarray]) -> trimesh.Trimesh:
    """``mesh.ply`` with its per-vertex properties as ``vertex_attributes``; the npz's mesh
    when there is no PLY."""
    if not ply.is_file():
        return trimesh.Trimesh(
            vertices=arrays["vertices"], faces=arrays["faces"], process=False
        )
    mesh = trimesh.load(ply, process=False)
    if not isinstance(mesh, trimesh.Trimesh):
        raise RigError(f"{ply} holds no triangle mesh", "run `rig reconstruct` again")
    data = mesh.metadata.get("_ply_raw", {}).get("vertex", {}).get("data")
    if data is not None and data.dtype.names:
        mesh.vertex_attributes.update(
            {name: np.asarray(data[name]) for name in data.dtype.names if name not in _GEOMETRY}
        )
    return mesh
