"""Depth-map pixels that look at the surface near its mirror direction, left out of fusion.

A glaze or varnish reflects the lamp where the surface's normal bisects the directions to the
lamp and to the camera. The lamp rides on the camera, so that highlight moves across the
surface from view to view: PatchMatch matches the moving highlight instead of the paint and
puts such pixels millimetres off, and neighbouring views' wrong depths can confirm each other.
Which pixels those are follows from the geometry alone: a first surface from all the fused
points (whose normals are right even where a blob displaces it) gives each pixel's normal,
and pixels within ``max_deg`` of the mirror direction are dropped before fusing again. The
views that see the same surface obliquely keep it. Concavities are seen head-on, though,
and with few views the head-on depths are much of what fusion confirms, so the pass runs by
default only for objects declared glossy.
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


def without_near_mirror(
    maps: Mapping[int, ViewDepth],
    poses: Mapping[int, Pose],
    light_offset: np.ndarray,
    surface: trimesh.Trimesh,
    max_deg: float,
) -> tuple[dict[int, ViewDepth], int]:
    """Each view's depth map with the pixels dropped (NaN) whose ray meets ``surface`` where
    its normal lies within ``max_deg`` of the half-vector of the directions to the camera and
    to the light at ``light_offset`` (camera frame, metres, as ``light_mount.offset_m``), and
    how many pixels were dropped. Pixels whose ray misses ``surface`` are kept."""
    caster = RayCaster(np.asarray(surface.vertices), np.asarray(surface.faces))
    face_normals = np.asarray(surface.face_normals)
    out: dict[int, ViewDepth] = {}
    dropped = 0
    for view, vd in maps.items():
        rows, cols = np.nonzero(np.isfinite(vd.distance))
        pose = poses[view]
        rays = vd.intrinsics.pixel_rays(np.stack([cols + 0.5, rows + 0.5], 1)) @ pose.R
        tri, distance, _ = caster.first_hit(np.broadcast_to(pose.center, rays.shape), rays)
        hit = tri >= 0
        points = pose.center + rays[hit] * distance[hit, None]
        n = len(points)
        angle = half_angles(
            points,
            face_normals[tri[hit]],
            np.broadcast_to(pose.light_position(light_offset), (n, 3)),
            np.broadcast_to(pose.center, (n, 3)),
        )
        near = angle < np.radians(max_deg)
        depth = vd.distance.copy()
        depth[rows[hit][near], cols[hit][near]] = np.nan
        dropped += int(near.sum())
        out[view] = replace(vd, distance=depth)
    return out, dropped
