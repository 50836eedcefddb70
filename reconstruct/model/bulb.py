"""A bulb with a size, as surface points see it: a uniform Lambertian sphere of radius r (its
radiance I / (π r²) for the point light's intensity I).

Its irradiance on a surface that sees all of it above the horizon is exactly the point
light's at its centre (a uniform sphere's field outside it is its centre's); only partial
views — the bulb across the horizon, or a penumbra — differ. The optimiser leaves those out
(:func:`rim_points` for the shadow rays); the simulator renders them (:func:`cone_samples`).
"""

from __future__ import annotations

import numpy as np

GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


def _across_sight(points: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (N, 3) across each point's line of sight to the bulb's centre."""
    sight = np.broadcast_to(np.asarray(centres, dtype=float), points.shape) - points
    sight = sight / np.linalg.norm(sight, axis=1, keepdims=True)
    # the axis each line of sight is least aligned with, crossed with it
    axis = np.eye(3)[np.argmin(np.abs(sight), axis=1)]
    across = np.cross(sight, axis)
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    return across, np.cross(sight, across)


def rim_points(points: np.ndarray, centres: np.ndarray, radius: float, count: int) -> np.ndarray:
    """``count`` points (count, N, 3) evenly around the rim of the bulb each point sees (the
    disc of its radius across the line of sight).

    >>> rim_points(np.zeros((1, 3)), np.array([0.0, 0.0, 1.0]), 0.1, 4)[:, 0, 2]
    array([1., 1., 1., 1.])
    """
    across, other = _across_sight(points, centres)
    phi = 2.0 * np.pi * np.arange(count) / count
    offset = np.cos(phi)[:, None, None] * across[None] + np.sin(phi)[:, None, None] * other[None]
    return np.broadcast_to(np.asarray(centres, dtype=float), points.shape)[None] + radius * offset


def cone_samples(
    points: np.ndarray, centres: np.ndarray, radius: float, count: int
) -> tuple[np.ndarray, np.ndarray]:
    """Points on the bulb (count, N, 3) along ``count`` directions spread evenly over the cone
    it subtends from each point, and the factor (N,) that turns the sum over them of
    ``max(0, cos θ) · visible`` into the irradiance in the point light's units (cos θ / d²
    for a bulb fully seen above the horizon, exactly: equal solid-angle strata, each direction
    paired with its opposite about the axis). ``count`` even.

    A surface facing a 6 cm bulb 0.5 m away gets the point light's 1 / 0.5²:

    >>> x, normal = np.zeros((1, 3)), np.array([0.0, 0.0, 1.0])
    >>> targets, scale = cone_samples(x, np.array([0.0, 0.0, 0.5]), 0.03, 16)
    >>> rays = targets - x
    >>> round(float(np.sum(rays @ normal / np.linalg.norm(rays, axis=-1)) * scale[0]), 9)
    4.0
    """
    centres = np.broadcast_to(np.asarray(centres, dtype=float), points.shape)
    sight = centres - points
    distance = np.linalg.norm(sight, axis=1)
    axis = sight / distance[:, None]
    sin_b = np.minimum(radius / distance, 1.0)
    cos_b = np.sqrt(1.0 - sin_b**2)
    pairs = np.arange(count // 2)
    # uniform in solid angle: cos of the angle to the axis uniform on [cos β, 1]
    z = 1.0 - ((pairs + 0.5) / pairs.size)[:, None] * (1.0 - cos_b)[None]
    z = np.concatenate([z, z])
    phi = np.concatenate([pairs * GOLDEN_ANGLE, pairs * GOLDEN_ANGLE + np.pi])[:, None, None]
    across, other = _across_sight(points, centres)
    directions = z[..., None] * axis[None] + np.sqrt(1.0 - z**2)[..., None] * (
        np.cos(phi) * across[None] + np.sin(phi) * other[None]
    )
    # where each direction meets the bulb's near surface
    reach = distance * z - np.sqrt(np.maximum(radius**2 - distance**2 * (1.0 - z**2), 0.0))
    targets = points[None] + directions * reach[..., None]
    solid_angle = 2.0 * np.pi * (1.0 - cos_b)
    return targets, solid_angle / (np.pi * radius**2 * count)
