"""The one forward image-formation model (docs/architecture.md, Forward model; paper eq. 12).

``y = m · s · C^T diag(L) r`` with ``s = max(0, (p − x)·n) / |p − x|³`` (near point light,
inverse square, Lambertian) and ``m`` the binary shadow mask. The simulated rig renders with
these functions, relighting renders with them and the optimiser inverts them, so a change of
convention happens here once. The sum over wavelength is a plain sum: the grid step is absorbed
into the SPD's scale (docs/architecture.md, Radiometry).
"""

from __future__ import annotations

import numpy as np

from calibration.estimation import response_matrices
from core.errors import RigError


def response_matrix(camera_sensitivity: np.ndarray, spd: np.ndarray) -> np.ndarray:
    """``C^T diag(L)``: camera sensitivity (N_λ, 3) and light SPD (N_λ,) -> (3, N_λ), one
    light of :func:`calibration.estimation.response_matrices`.

    Multiplying a reflectance (N_λ,) by it gives the RGB of a unit-shading, unshadowed point.
    """
    L = np.asarray(spd, dtype=float)
    if L.ndim != 1:
        raise RigError(
            f"the light SPD has shape {L.shape}, expected one spectrum (N_λ,)",
            "pass one light's SPD, or use calibration.estimation.response_matrices for several",
        )
    return response_matrices(camera_sensitivity, L[None, :])[0]


def shading(points: np.ndarray, normals: np.ndarray, light_positions: np.ndarray) -> np.ndarray:
    """Shading factor ``max(0, (p − x)·n) / |p − x|³`` (paper eq. 8), shape (N,).

    ``points`` and ``normals`` are (N, 3) (normals unit length); ``light_positions`` is one
    light (3,) or one per point (N, 3). Distances in metres.
    """
    x = np.asarray(points, dtype=float)
    n = np.asarray(normals, dtype=float)
    d = np.asarray(light_positions, dtype=float) - x
    dist2 = np.einsum("ij,ij->i", d, d)  # 3× faster than norm(axis=-1) and ** 3 at 1M points
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.einsum("ij,ij->i", d, n) / (dist2 * np.sqrt(dist2))
    return np.where(np.isfinite(s), np.maximum(s, 0.0), 0.0)


def render_values(
    reflectance: np.ndarray,
    shading: np.ndarray,
    response: np.ndarray,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Rendered linear RGB ``m · s · (C^T L) r`` per point, shape (N, 3).

    ``reflectance`` (N, N_λ), ``shading`` (N,), ``response`` (3, N_λ) from
    :func:`response_matrix`, ``mask`` (N,) bool, True = lit (unoccluded).
    """
    r = np.asarray(reflectance, dtype=float)
    weight = np.asarray(shading, dtype=float)
    if mask is not None:
        weight = weight * np.asarray(mask, dtype=bool)
    return weight[:, None] * (r @ np.asarray(response, dtype=float).T)
