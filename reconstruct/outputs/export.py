"""Files of ``SESSION/recon/`` that other tools read (names and layouts are fixed):

* ``mesh.ply`` — binary little-endian PLY: ``x y z`` (float, metres), ``nx ny nz`` (float),
  ``red green blue`` (uchar, sRGB of the reflectance under D65) and ``refl_400 … refl_700``
  (float, the reflectance per grid wavelength), with an uncertainty ``refl_std_400 …
  refl_std_700`` and ``position_std_m`` (float, NaN where not estimated), triangle faces as
  ``vertex_indices``;
* ``reflectance.npz`` — ``vertices`` (N, 3), ``faces`` (F, 3), ``wavelengths_nm`` (N_λ,),
  ``reflectance`` (N, N_λ), ``alpha`` (N, N_b), ``basis`` (N_λ, N_b), ``normals``, ``observed``,
  with an uncertainty ``reflectance_std`` (N, N_λ) and ``position_std_m`` (N,) (std along the
  normal; NaN where not estimated) and ``reflectance_low``/``reflectance_high`` (N, N_λ), the
  95 % band inside the physical range, and ``colour_source`` (N,) int, the vertex whose
  reflectance each carries (itself, or a settled neighbour where its shape was left folded);
* ``report.json`` — see :func:`write_report`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from calibration.colorimetry import reflectance_to_srgb
from calibration.grid import SpectralGrid
from core.errors import RigError
from core.files import atomic_output, write_bytes_atomically

MESH_FILE = "mesh.ply"
REFLECTANCE_FILE = "reflectance.npz"
REPORT_FILE = "report.json"


def write_ply(
    path: Path,
    vertices: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray,
    reflectance: np.ndarray,
    wavelengths_nm: np.ndarray,
    extra: Mapping[str, np.ndarray] | None = None,
) -> Path:
    """Binary PLY with per-vertex sRGB (D65) and the spectral reflectance as float properties;
    ``extra``: more float vertex properties by name, (N,) each."""
    n = len(vertices)
    wl = [int(round(w)) for w in np.asarray(wavelengths_nm)]
    if reflectance.shape != (n, len(wl)):
        raise RigError(
            f"reflectance has shape {reflectance.shape}, expected ({n}, {len(wl)})",
            "give one spectrum per vertex on the grid",
        )
    srgb = reflectance_to_srgb(
        reflectance, SpectralGrid.from_wavelengths(np.asarray(wavelengths_nm))
    )
    rgb8 = np.clip(np.round(srgb * 255.0), 0, 255).astype(np.uint8)
    # every property a named 1-D attribute: trimesh writes each as `property <type> <name>`,
    # in this order, after x y z and nx ny nz
    attributes: dict[str, Any] = {
        name: rgb8[:, k] for k, name in enumerate(("red", "green", "blue"))
    }
    attributes |= {f"refl_{w}": reflectance[:, k].astype("<f4") for k, w in enumerate(wl)}
    attributes |= {name: np.asarray(v, "<f4") for name, v in (extra or {}).items()}
    mesh = trimesh.Trimesh(
        vertices=vertices,
        faces=faces,
        vertex_normals=normals,
        vertex_attributes=attributes,
        process=False,
    )
    data = trimesh.exchange.ply.export_ply(mesh, encoding="binary", vertex_normal=True)
    write_bytes_atomically(path, data)
    return path


def write_reflectance_npz(
    path: Path,
    vertices: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray,
    wavelengths_nm: np.ndarray,
    reflectance: np.ndarray,
    alpha: np.ndarray,
    basis: np.ndarray,
    observed: np.ndarray,
    extra_arrays: Mapping[str, np.ndarray] | None = None,
) -> Path:
    """``extra_arrays``: e.g. ``reflectance_std`` and ``position_std_m`` when estimated, and
    ``initial_reflectance`` (the 2-D estimate the solve started from)."""
    arrays = {
        "vertices": vertices,
        "faces": faces,
        "normals": normals,
        "wavelengths_nm": wavelengths_nm,
        "reflectance": reflectance,
        "alpha": alpha,
        "basis": basis,
        "observed": observed,
        **dict(extra_arrays or {}),
    }
    with atomic_output(path) as tmp:
        np.savez_compressed(tmp, **arrays)  # type: ignore[arg-type]
    return path


def read_reflectance_npz(path: Path) -> dict[str, np.ndarray]:
    """The arrays of a ``reflectance.npz`` (RigError naming the file and what is missing)."""
    need = ("vertices", "faces", "wavelengths_nm", "reflectance")
    try:
        with np.load(path, allow_pickle=False) as data:
            out = {k: np.asarray(data[k]) for k in data.files}
    except (OSError, ValueError) as error:
        raise RigError(
            f"cannot read {path}: {error}", "run `rig reconstruct SESSION` first"
        ) from error
    missing = [k for k in need if k not in out]
    if missing:
        raise RigError(
            f"{path} lacks {', '.join(missing)}", "it is not a spectral-rig reconstruction"
        )
    return out


def write_report(path: Path, report: dict[str, Any]) -> Path:
    """``report.json``: at least ``light`` (``offset_m``, ``positions_m``), ``history`` (each
    cost term per iteration), ``timings_s``, ``settings`` and ``reflectance_scale_absolute``."""
    write_bytes_atomically(path, (json.dumps(_plain(report), indent=2) + "\n").encode())
    return path


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value
