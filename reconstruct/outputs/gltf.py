"""A reconstruction as one glTF 2.0 binary (``.glb``) for Blender, three.js or a web viewer,
written by trimesh's glTF exporter.

* ``POSITION`` (metres) and ``NORMAL``, turned from the reconstruction's z-up frame into
  glTF's y-up frame (x, y, z) -> (x, z, -y);
* ``COLOR_0``: the reflectance seen under one illuminant as *linear* sRGB (glTF viewers apply
  the transfer function themselves), unsigned bytes normalised to [0, 1];
* ``_REFLECTANCE_400`` … ``_REFLECTANCE_700``: the reflectance per grid wavelength, one float
  per vertex each (glTF's custom attributes start with an underscore);
* the mesh's ``extras``: ``wavelengths_nm``, ``illuminant`` and ``color_0`` (what COLOR_0 is).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from calibration.colorimetry import reflectance_to_srgb
from calibration.grid import SpectralGrid
from core.files import write_bytes_atomically
from reconstruct.outputs.result import ReconstructionResult

# z up (the reconstruction, the board's frame) -> y up (glTF)
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def reflectance_attribute(wavelength_nm: float) -> str:
    return f"_REFLECTANCE_{int(round(wavelength_nm))}"


def linear_colours(result: ReconstructionResult, illuminant: np.ndarray) -> np.ndarray:
    """(N, 3) linear sRGB in [0, 1] of each vertex's reflectance under ``illuminant``."""
    grid = SpectralGrid.from_wavelengths(result.wavelengths_nm)
    return reflectance_to_srgb(result.reflectance, grid, illuminant, linear=True)


def write_glb(
    path: Path, result: ReconstructionResult, illuminant: np.ndarray, illuminant_name: str
) -> Path:
    """``path`` (.glb) holding ``result``'s mesh, colours under ``illuminant`` (an SPD on the
    result's grid) and spectra."""
    vertices = np.asarray(result.mesh.vertices, float) @ Z_UP_TO_Y_UP.T
    normals = np.asarray(result.mesh.vertex_normals, float) @ Z_UP_TO_Y_UP.T
    rgb = np.round(linear_colours(result, illuminant) * 255.0).astype(np.uint8)
    alpha = np.full((len(rgb), 1), 255, np.uint8)
    spectra: dict[str, Any] = {
        reflectance_attribute(w): result.reflectance[:, k].astype(np.float32)
        for k, w in enumerate(result.wavelengths_nm)
    }
    mesh = trimesh.Trimesh(
        vertices=vertices,
        faces=np.asarray(result.mesh.faces),
        vertex_normals=normals,
        vertex_colors=np.hstack([rgb, alpha]),
        vertex_attributes=spectra,
        metadata={
            "wavelengths_nm": [float(w) for w in result.wavelengths_nm],
            "illuminant": illuminant_name,
            "color_0": f"linear sRGB of the reflectance under {illuminant_name}",
        },
        process=False,
    )
    data = trimesh.exchange.gltf.export_glb(trimesh.Scene(mesh), include_normals=True)
    write_bytes_atomically(path, data)
    return path
