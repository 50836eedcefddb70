"""One self-contained HTML page (plotly.js embedded: no network) showing a reconstruction: the
mesh coloured in sRGB under a chosen illuminant, recomputed in the browser from the per-vertex
spectra; a click on the mesh plots that vertex's spectrum (with the 2-D initial estimate and the
truth when known); cameras and estimated lights; the spectral-error map when a truth exists."""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
from plotly.offline import get_plotlyjs

from core.files import write_bytes_atomically
from core.lock import output_lock
from rig.view import pack
from rig.view.data import ViewData


def payload(data: ViewData, matrices: dict[str, np.ndarray]) -> dict[str, Any]:
    """The page's data: arrays packed by :mod:`rig.view.pack` (about 40-60 bytes a vertex)."""
    n, bands = data.reflectance.shape
    basis = np.zeros((bands, 0)) if data.basis is None else np.asarray(data.basis, float)
    return {
        "name": data.name,
        "n": n,
        "bands": bands,
        "wavelengths": data.wavelengths_nm.tolist(),
        "basis": basis.tolist(),
        "vertices": pack.positions(data.vertices),
        "faces": pack.deflated(data.faces.astype("<i4")),
        "reflectance": pack.spectra(data.reflectance, basis),
        "initial": None if data.initial is None else pack.spectra(data.initial, basis),
        "truth": None if data.truth is None else pack.spectra(data.truth, basis),
        "observed": pack.deflated(data.observed.astype("u1")),
        "cameras": data.cameras.tolist(),
        "lights": data.lights.tolist(),
        "illuminants": {name: m.ravel().tolist() for name, m in matrices.items()},
    }


def build_page(data: ViewData, matrices: dict[str, np.ndarray]) -> str:
    body = json.dumps(payload(data, matrices))
    return (
        files("rig.view").joinpath("viewer.html").read_text(encoding="utf-8")
        .replace("__TITLE__", f"spectral-rig: {data.name}")
        .replace("__PLOTLY__", get_plotlyjs())
        .replace("__DATA__", body)
    )


def export_page(path: Path, page: str) -> None:
    """Write the page to ``path`` (whole or not at all); into a session only while no other
    command writes it."""
    with output_lock(path, "rig view --export"):
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomically(path, page.encode("utf-8"))
