"""One self-contained HTML page (plotly.js embedded: no network) showing a reconstruction: the
mesh coloured in sRGB under a chosen illuminant, recomputed in the browser from the per-vertex
spectra; a click on the mesh plots that vertex's spectrum (with the 2-D initial estimate and the
truth when known); cameras and estimated lights; the spectral-error map when a truth exists."""

from __future__ import annotations

import base64
import json
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
from plotly.offline import get_plotlyjs

from core.files import write_bytes_atomically
from core.lock import output_lock
from rig.view.data import ViewData


def _b64(array: np.ndarray, dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode()


def payload(data: ViewData, matrices: dict[str, np.ndarray]) -> dict[str, Any]:
    """The page's data: float32/float16 arrays as base64 little-endian bytes."""
    n, bands = data.reflectance.shape
    error = data.spectral_error
    return {
        "name": data.name,
        "n": n,
        "bands": bands,
        "wavelengths": data.wavelengths_nm.tolist(),
        "vertices": _b64(data.vertices, "<f4"),
        "faces": _b64(data.faces, "<i4"),
        "reflectance": _b64(data.reflectance, "<f2"),
        "initial": None if data.initial is None else _b64(data.initial, "<f2"),
        "truth": None if data.truth is None else _b64(data.truth, "<f2"),
        "error": None if error is None else _b64(error, "<f4"),
        "observed": _b64(data.observed, "u1"),
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
