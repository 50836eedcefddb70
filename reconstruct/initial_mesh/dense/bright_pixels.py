"""Depth-map pixels brighter than their surface point looks from the other views, left out
of fusion.

A glaze's highlight adds the lamp's own light to a pixel (the dichromatic model), and the lamp
rides on the camera, so the highlight sits on a different part of the surface in every view.
Where paint is uniform the highlight is the only texture PatchMatch finds, and it matches the
moving highlight instead of the surface. The near-mirror test
(:mod:`reconstruct.initial_mesh.dense.mirror`) finds those pixels from the first surface's
normals, which are wrong exactly where that surface has a highlight's blob; this test asks the
images instead. With the lamp at the camera a Lambertian point's brightness divided by its
shading (:func:`reconstruct.model.forward.shading`, with the first surface's normals averaged
over a patch wider than a blob) is the same in every view; its median over the views that see
the point is the point's diffuse level, since few of them see the highlight. A pixel more
than ``ratio`` times the brightest level on and around the face its ray meets is dropped,
with the pixels whose matching window reaches it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import cv2
import numpy as np
import trimesh
from scipy.ndimage import map_coordinates

from reconstruct.initial_mesh.dense.mirror import (
    AVERAGE_FRACTION,
    averaged_vertex_normals,
    face_normals_of,
    surface_hits,
)
from reconstruct.initial_mesh.dense.patchmatch import ViewDepth
from reconstruct.model.camera import Pose, project
from reconstruct.model.forward import shading
from reconstruct.model.raycast import RayCaster

# views a point must be seen in for its median to be its diffuse level
MIN_LEVEL_VIEWS = 3
# the least shading, relative to head-on at the same distance, a level is estimated from
# (grazing: the brightness is mostly noise and the normal's error)
MIN_COS = 0.2


def lit(shade: np.ndarray, points: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Whether points (N, 3) with ``shade`` (:func:`shading`) under ``light`` (3,) are lit
    at least :data:`MIN_COS` of head-on at their distance."""
    return shade > MIN_COS / np.sum((light - points) ** 2, axis=1)


def diffuse_levels(
    surface: trimesh.Trimesh,
    normals: np.ndarray,
    images: Mapping[int, np.ndarray],
    masks: Mapping[int, np.ndarray],
    maps: Mapping[int, ViewDepth],
    poses: Mapping[int, Pose],
    light_offset: np.ndarray,
    caster: RayCaster | None = None,
) -> np.ndarray:
    """Per vertex of ``surface`` (V,): the median over the views that see it of its
    brightness (the sum of a view's channels, bilinear at its projection) divided by its
    shading under that view's lamp; NaN where fewer than :data:`MIN_LEVEL_VIEWS` views see
    it. ``normals`` (V, 3) are the vertices' (averaged) unit normals; a view's reading counts
    only inside its ``masks`` (H, W) bool and a pixel away from its silhouette's edge, where
    the bilinear taps would blend in the background. ``caster``: ``surface``'s, if built."""
    caster = caster or RayCaster(np.asarray(surface.vertices), np.asarray(surface.faces))
    points = np.asarray(surface.vertices, dtype=float)
    views = sorted(maps)
    levels = np.full((len(points), len(views)), np.nan)
    for col, view in enumerate(views):
        pose, intr = poses[view], maps[view].intrinsics
        uv = project(intr, pose, points)
        light = pose.light_position(light_offset)
        s = shading(points, normals, light)
        cand = np.flatnonzero(intr.in_image(uv, 1.0) & lit(s, points, light))
        inner = cv2.erode(masks[view].astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        cand = cand[inner[uv[cand, 1].astype(int), uv[cand, 0].astype(int)]]
        seen = cand[~caster.occluded(points[cand], pose.center, 1e-4, normals[cand])]
        bright = images[view].sum(axis=2)
        coords = [uv[seen, 1] - 0.5, uv[seen, 0] - 0.5]
        levels[seen, col] = map_coordinates(bright, coords, order=1, mode="nearest") / s[seen]
    enough = np.sum(np.isfinite(levels), axis=1) >= MIN_LEVEL_VIEWS
    out = np.full(len(points), np.nan)
    out[enough] = np.nanmedian(levels[enough], axis=1)
    return out


def without_bright(
    maps: Mapping[int, ViewDepth],
    images: Mapping[int, np.ndarray],
    masks: Mapping[int, np.ndarray],
    poses: Mapping[int, Pose],
    light_offset: np.ndarray,
    surface: trimesh.Trimesh,
    ratio: float,
    reach_px: int,
    average_fraction: float = AVERAGE_FRACTION,
) -> tuple[dict[int, ViewDepth], int]:
    """Each view's depth map with the pixels dropped (NaN) whose brightness over shading
    exceeds ``ratio`` times the brightest diffuse level (:func:`diffuse_levels`) on and
    around the face of ``surface`` their ray meets, and those within ``reach_px`` pixels of
    one, and how many pixels were dropped. ``images`` (H, W, C) and ``masks`` are the views
    as PatchMatch matched them, at the depth maps' scale; ``light_offset`` is the lamp in the
    camera frame (metres). Pixels whose ray misses ``surface``, whose point has no level or
    is lit at a grazing angle are kept."""
    radius = average_fraction * float(max(surface.extents))
    normals = averaged_vertex_normals(surface, radius)
    faces = np.asarray(surface.faces)
    caster = RayCaster(np.asarray(surface.vertices), faces)
    levels = diffuse_levels(surface, normals, images, masks, maps, poses, light_offset, caster)
    # the brightest level among the corners and their neighbours: beside an edge of the paint
    # a pixel and the levels read there each mix the two paints in their own proportions
    nearby = levels.copy()
    edges = np.asarray(surface.edges_unique)
    np.fmax.at(nearby, edges[:, 0], levels[edges[:, 1]])
    np.fmax.at(nearby, edges[:, 1], levels[edges[:, 0]])
    face_level = np.max(nearby[faces], axis=1)
    face_normal = face_normals_of(surface, normals)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach_px + 1,) * 2)
    out: dict[int, ViewDepth] = {}
    dropped = 0
    for view, vd in maps.items():
        pose = poses[view]
        rows, cols, tri, points = surface_hits(vd, pose, caster)
        light = pose.light_position(light_offset)
        s = shading(points, face_normal[tri], light)
        bright = images[view].sum(axis=2)[rows, cols]
        with np.errstate(invalid="ignore"):
            over = (bright > ratio * face_level[tri] * s) & lit(s, points, light)
        bright_mask = np.zeros(vd.distance.shape, np.uint8)
        bright_mask[rows[over], cols[over]] = 1
        dropped_here = cv2.dilate(bright_mask, kernel) if reach_px else bright_mask
        depth = np.where(dropped_here.astype(bool), np.nan, vd.distance)
        dropped += int(np.isfinite(vd.distance).sum() - np.isfinite(depth).sum())
        out[view] = replace(vd, distance=depth)
    return out, dropped
