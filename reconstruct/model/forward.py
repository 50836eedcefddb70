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


def half_angles(
    points: np.ndarray, normals: np.ndarray, lights: np.ndarray, cameras: np.ndarray
) -> np.ndarray:
    """Angle (radians) between each normal and the half-vector of the directions to the light
    and to the camera centre (all (M, 3)): 0 where the camera sees the light's mirror image."""
    to_light, to_cam = lights - points, cameras - points
    half = to_light / np.linalg.norm(to_light, axis=1, keepdims=True)
    half += to_cam / np.linalg.norm(to_cam, axis=1, keepdims=True)
    cos = np.einsum("ij,ij->i", normals, half) / np.linalg.norm(half, axis=1)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def ggx_lobe(
    normals: np.ndarray,
    to_light: np.ndarray,
    to_eye: np.ndarray,
    alpha: float,
    specular: float = 1.0,
) -> np.ndarray:
    """``π f_s cos θ_l`` of a neutral GGX lobe per point (N,), from unit normals and unit
    directions to the light and the eye (N, 3): Trowbridge–Reitz D, Smith's separable G,
    Schlick's Fresnel from ``specular`` (the reflectance at normal incidence; 1: none). Times
    ``s / cos θ_l`` (the light's irradiance) and the lamp's own RGB it is a gloss highlight
    in this model's units, where a white Lambertian point returns ``s``.
    """
    half = to_light + to_eye
    half = half / np.linalg.norm(half, axis=1, keepdims=True)
    cos_l = np.einsum("ij,ij->i", normals, to_light)
    cos_v = np.einsum("ij,ij->i", normals, to_eye)
    cos_h = np.einsum("ij,ij->i", normals, half)
    a2 = alpha * alpha
    d = a2 / (np.pi * (cos_h**2 * (a2 - 1.0) + 1.0) ** 2)

    def g1(c: np.ndarray) -> np.ndarray:
        c = np.clip(c, 1e-6, 1.0)
        return 2.0 * c / (c + np.sqrt(a2 + (1.0 - a2) * c * c))

    fresnel = specular + (1.0 - specular) * (1.0 - np.einsum("ij,ij->i", to_eye, half)) ** 5
    lobe = np.pi * d * g1(cos_l) * g1(cos_v) * fresnel / (4.0 * np.clip(cos_v, 1e-6, None))
    return np.where((cos_l > 0) & (cos_v > 0), lobe, 0.0)
