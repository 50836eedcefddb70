"""Depth-map pixels that look at the surface near its mirror direction, left out of fusion.

A glaze or varnish reflects the lamp where the surface's normal bisects the directions to the
lamp and to the camera. The lamp rides on the camera, so that highlight moves across the
surface from view to view: PatchMatch matches the moving highlight instead of the paint and
puts such pixels millimetres off, and neighbouring views' wrong depths can confirm each other.
Which pixels those are follows from the geometry alone: a first surface from all the fused
points gives each pixel's normal, and pixels within ``max_deg`` of the mirror direction are
dropped before fusing again. Where that surface has a blob, the blob is a pit whose walls
tilt its normals away from the mirror direction; the walls tilt opposite ways, so the
normals averaged over a patch wider than the pit are the surface's underneath, and a pixel
is dropped when either normal puts it near the mirror direction. The views that see the
same surface obliquely keep it. Concavities are seen head-on, though, and with few views the
head-on depths are much of what fusion confirms, so the pass runs by default only for
objects declared glossy and seen from at least ``MIN_VIEWS`` views.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np
import trimesh

from reconstruct.initial_mesh.dense.patchmatch import ViewDepth
from reconstruct.model.camera import Pose
from reconstruct.model.forward import half_angles
from reconstruct.model.raycast import RayCaster

# the angle a glossy object's pixels are left out within (GGX α 0.2: the lobe is down to about
# a fifteenth of its peak there)
GLOSSY_MIRROR_DEG = 20.0
# fewer views than this and the pass costs a glossy object more than the highlights do
MIN_VIEWS = 24
# the patch the normals are also averaged over, as a fraction of the surface's longest side
# (a highlight's blob on a 20 cm object is a few millimetres across)
AVERAGE_FRACTION = 1 / 24


def averaged_vertex_normals(surface: trimesh.Trimesh, radius: float) -> np.ndarray:
    """The vertex normals (V, 3) of ``surface`` averaged over about ``radius`` (metres):
    repeated 1-ring means, a diffusion whose reach grows as the edge length times the square
    root of the number of steps.

    >>> sphere = trimesh.creation.icosphere(subdivisions=3)
    >>> n = averaged_vertex_normals(sphere, 0.3)
    >>> bool(np.all(np.einsum("ij,ij->i", n, sphere.vertex_normals) > 0.99))
    True
    """
    edge = float(np.mean(surface.edges_unique_length))
    steps = int(np.ceil((radius / edge) ** 2))
    ring_mean = trimesh.smoothing.laplacian_calculation(surface).tocsr()
    normals = np.array(surface.vertex_normals, dtype=float)
    for _ in range(steps):
        normals = ring_mean @ normals
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def face_normals_of(surface: trimesh.Trimesh, vertex_normals: np.ndarray) -> np.ndarray:
    """Unit face normals (F, 3): the mean of each face's corners' ``vertex_normals`` (V, 3).

    >>> sphere = trimesh.creation.icosphere(subdivisions=3)
    >>> n = face_normals_of(sphere, averaged_vertex_normals(sphere, 0.3))
    >>> bool(np.all(np.einsum("ij,ij->i", n, sphere.face_normals) > 0.99))
    True
    """
    face = vertex_normals[np.asarray(surface.faces)].sum(axis=1)
    return face / np.linalg.norm(face, axis=1, keepdims=True)


def surface_hits(
    vd: ViewDepth, pose: Pose, caster: RayCaster
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rows, columns, hit faces and world points (M, 3) of a depth map's finite pixels
    whose rays meet the surface ``caster`` holds."""
    rows, cols = np.nonzero(np.isfinite(vd.distance))
    rays = vd.intrinsics.pixel_rays(np.stack([cols + 0.5, rows + 0.5], 1)) @ pose.R
    tri, distance, _ = caster.first_hit(np.broadcast_to(pose.center, rays.shape), rays)
    hit = tri >= 0
    return rows[hit], cols[hit], tri[hit], pose.center + rays[hit] * distance[hit, None]


def without_near_mirror(
    maps: Mapping[int, ViewDepth],
    poses: Mapping[int, Pose],
    light_offset: np.ndarray,
    surface: trimesh.Trimesh,
    max_deg: float,
    average_fraction: float = AVERAGE_FRACTION,
) -> tuple[dict[int, ViewDepth], int]:
    """Each view's depth map with the pixels dropped (NaN) whose ray meets ``surface`` where
    its normal, or that normal averaged over ``average_fraction`` of the surface's longest
    side around it, lies within ``max_deg`` of the half-vector of the directions to the camera
    and to the light at ``light_offset`` (camera frame, metres, as ``light_mount.offset_m``),
    and how many pixels were dropped. Pixels whose ray misses ``surface`` are kept."""
    caster = RayCaster(np.asarray(surface.vertices), np.asarray(surface.faces))
    normals = [np.asarray(surface.face_normals)]
    if average_fraction > 0:
        radius = average_fraction * float(max(surface.extents))
        normals.append(face_normals_of(surface, averaged_vertex_normals(surface, radius)))
    limit = np.radians(max_deg)
    out: dict[int, ViewDepth] = {}
    dropped = 0
    for view, vd in maps.items():
        pose = poses[view]
        rows, cols, tri, points = surface_hits(vd, pose, caster)
        n = len(points)
        lights = np.broadcast_to(pose.light_position(light_offset), (n, 3))
        cameras = np.broadcast_to(pose.center, (n, 3))
        near = np.zeros(n, dtype=bool)
        for face_normals in normals:
            near |= half_angles(points, face_normals[tri], lights, cameras) < limit
        depth = vd.distance.copy()
        depth[rows[near], cols[near]] = np.nan
        dropped += int(near.sum())
        out[view] = replace(vd, distance=depth)
    return out, dropped
