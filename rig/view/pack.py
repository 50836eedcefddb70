"""The viewer page's arrays, small: quantised to integers, split into byte planes (the high
bytes of neighbouring values are alike), deflated with zlib and base64-encoded. The page
inflates them with the browser's ``DecompressionStream('deflate')``.

Spectra go as coefficients in the reconstruction's reflectance basis plus a residual, both
quantised: the optimiser's spectra lie in the basis (their residual is zeros, which deflate
to almost nothing) and any other spectrum (the truth) keeps its detail in the residual. Every
value the page rebuilds is within half a residual step of the original: 1/4096 while the
residuals stay within ±16, coarser only beyond."""

from __future__ import annotations

import base64
import zlib
from typing import Any

import numpy as np

STEP = 1.0 / 2048  # quantisation step of coefficients and residuals (reflectance units)
INT16_MAX = 32767


def deflated(values: np.ndarray) -> str:
    """A little-endian integer array as base64 of its deflated byte planes."""
    values = np.ascontiguousarray(values)
    size = values.dtype.itemsize
    planes = values.view(np.uint8).reshape(-1, size).T
    return base64.b64encode(zlib.compress(planes.tobytes(), 9)).decode()


def _quantised(values: np.ndarray) -> tuple[np.ndarray, float]:
    """int16 values and their step: :data:`STEP`, or coarser when a value would not fit."""
    biggest = float(np.max(np.abs(values), initial=0.0))
    step = max(STEP, biggest / INT16_MAX)
    return np.round(values / step).astype("<i2"), step


def spectra(values: np.ndarray, basis: np.ndarray) -> dict[str, Any]:
    """(N, L) spectra as ``basis`` (L, K; K may be 0) coefficients plus a residual."""
    values = np.nan_to_num(np.asarray(values, float))
    if basis.shape[1]:
        coefficients = np.linalg.lstsq(basis, values.T, rcond=None)[0].T
    else:
        coefficients = np.zeros((len(values), 0))
    q_coefficients, coefficient_step = _quantised(coefficients)
    rebuilt = (q_coefficients * coefficient_step) @ basis.T
    q_residual, residual_step = _quantised(values - rebuilt)
    return {
        "coefficients": deflated(q_coefficients),
        "coefficient_step": coefficient_step,
        "residual": deflated(q_residual),
        "residual_step": residual_step,
    }


def positions(vertices: np.ndarray) -> dict[str, Any]:
    """(N, 3) positions as uint16 steps across their bounding box (1/65535 of its size)."""
    lo = vertices.min(axis=0) if len(vertices) else np.zeros(3)
    step = np.maximum(np.ptp(vertices, axis=0) if len(vertices) else np.ones(3), 1e-12) / 65535
    q = np.round((vertices - lo) / step).astype("<u2")
    return {"values": deflated(q), "origin": lo.tolist(), "step": step.tolist()}
