"""Depth-map pixels brighter than their surface point looks from the other views, left out
of fusion.

A glaze's highlight adds the lamp's own light to a pixel (the dichromatic model), and the lamp
rides on the camera, so the highlight sits on a different part of the surface in every view.
Where paint is uniform the highlight is the only texture PatchMatch finds, and it matches the
moving highlight instead of the surface. The near-mirror test
(:mod:`reconstruct.initial_mesh.dense.mirror`) finds those pixels from the first surface's
normals, which are wrong exactly where that surface has a highlight's blob; this test asks the
images instead. With the lamp at the camera every view lights the surface from its own
direction, so the views are a near-field photometric stereo: a Lambertian point's brightness
in view ``k`` is ``g · u_k``, with ``g`` its albedo times its normal and ``u_k`` its lamp
vector (:func:`lamp_vectors`). ``g`` is fitted per vertex of the first surface by least
squares, leaving out the readings far above the fit (the highlights, seen by few views) and
refitting. A pixel more than ``ratio`` times the brightest fitted brightness on and around the
face its ray meets is dropped, with the pixels whose matching window reaches it. The fitted
normal is the images' own, so it holds where the first surface is deformed and where its
normals smoothed over a patch miss fine relief, the two places a fixed normal made the test
drop matte pixels.
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

# the ratio a glossy object's pixels are judged at: above the fit's noise and a lobe's flanks
# (bench/README.md, "Highlights found by a photometric fit")
GLOSSY_BRIGHT_RATIO = 1.2
# readings a vertex's fit needs: one more than its three unknowns, so that a reading left over
# can disagree
MIN_FIT_VIEWS = 4
# the least ratio of the directions' weakest to strongest spread a fit is trusted with
# (views from a narrow cone leave the normal's tilt across it unknown)
MIN_SPREAD = 0.05
# readings above this times the fit are left out of the next fit as highlights
HIGHLIGHT_FIT_RATIO = 1.15
# refits after the first, each without the previous fit's highlights
REFITS = 3
# the least shading, relative to head-on at the same distance, a pixel is judged at
# (grazing: the brightness is mostly noise and the normal's error)
MIN_COS = 0.2
# vertices fitted at once (bounds the fit's float64 working copies of the readings)
FIT_BLOCK = 65536


def lit(shade: np.ndarray, points: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Whether points (N, 3) with ``shade`` (:func:`shading`) under ``light`` (3,) are lit
    at least :data:`MIN_COS` of head-on at their distance."""
    return shade > MIN_COS / np.sum((light - points) ** 2, axis=1)


def lamp_vectors(points: np.ndarray, light: np.ndarray) -> np.ndarray:
    """``(p − x) / |p − x|³`` (N, 3) for points ``x`` (N, 3) and a lamp ``p`` (3,): a lit
    Lambertian point's brightness is its albedo-normal dotted with it (:func:`shading`).

    >>> x = np.array([[0.0, 0.0, 0.0]])
    >>> lamp_vectors(x, np.array([0.0, 0.0, 0.5])).tolist()
    [[0.0, 0.0, 4.0]]
    """
    d = light - points
    return d / np.linalg.norm(d, axis=1, keepdims=True) ** 3


def view_readings(
    surface: trimesh.Trimesh,
    normals: np.ndarray,
    images: Mapping[int, np.ndarray],
    masks: Mapping[int, np.ndarray],
    maps: Mapping[int, ViewDepth],
    poses: Mapping[int, Pose],
    light_offset: np.ndarray,
    caster: RayCaster,
) -> tuple[np.ndarray, np.ndarray]:
    """Per vertex of ``surface`` and view (in sorted order): its brightness (the sum of the
    view's channels, bilinear at its projection; NaN where the view does not see it) (V, K)
    and its lamp vector (:func:`lamp_vectors`) (V, K, 3), float32. A view's reading counts
    only inside its ``masks`` (H, W) bool and a pixel away from its silhouette's edge, where
    the bilinear taps would blend in the background; ``normals`` (V, 3) lift the occlusion
    test's rays off the surface."""
    points = np.asarray(surface.vertices, dtype=float)
    views = sorted(maps)
    brightness = np.full((len(points), len(views)), np.nan, np.float32)
    vectors = np.zeros((len(points), len(views), 3), np.float32)
    for col, view in enumerate(views):
        pose, intr = poses[view], maps[view].intrinsics
        uv = project(intr, pose, points)
        cand = np.flatnonzero(intr.in_image(uv, 1.0))
        inner = cv2.erode(masks[view].astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        cand = cand[inner[uv[cand, 1].astype(int), uv[cand, 0].astype(int)]]
        seen = cand[~caster.occluded(points[cand], pose.center, 1e-4, normals[cand])]
        coords = [uv[seen, 1] - 0.5, uv[seen, 0] - 0.5]
        brightness[seen, col] = map_coordinates(
            images[view].sum(axis=2), coords, order=1, mode="nearest")
        vectors[seen, col] = lamp_vectors(points[seen], pose.light_position(light_offset))
    return brightness, vectors


def _least_squares(
    brightness: np.ndarray, vectors: np.ndarray, use: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per vertex the ``g`` (V, 3) minimising the squared error of ``vectors · g`` (V, K, 3)
    against ``brightness`` (V, K) over the readings ``use`` (V, K) bool, and their
    ``vectors``' Gram matrix scaled to unit mean eigenvalue (V, 3, 3)."""
    gram = np.einsum("vk,vki,vkj->vij", use, vectors, vectors)
    # scaled, so that the regularising ridge is the same at any distance
    scale = np.trace(gram, axis1=1, axis2=2)[:, None, None] / 3 + 1e-30
    gram = gram / scale
    rhs = np.einsum("vk,vk,vki->vi", use, brightness, vectors)[..., None] / scale
    return np.linalg.solve(gram + 1e-9 * np.eye(3), rhs)[..., 0], gram


def fit_albedo_normals(
    brightness: np.ndarray, vectors: np.ndarray, start_normals: np.ndarray
) -> np.ndarray:
    """Per vertex the albedo-normal ``g`` (V, 3) with ``brightness ≈ vectors · g``
    (:func:`view_readings`), by least squares over the readings that face ``start_normals``
    (V, 3), then :data:`REFITS` times over those that the last fit lights and that exceed it
    by no more than :data:`HIGHLIGHT_FIT_RATIO` times. NaN where fewer than :data:`MIN_FIT_VIEWS`
    readings are left or their lamp directions spread less than :data:`MIN_SPREAD`.

    >>> n = np.array([[0.0, 0.0, 1.0]])
    >>> u = np.array([[[0.0, 0.0, 4.0], [1.0, 0.0, 3.0], [0.0, 1.0, 3.0], [-1.0, 0.0, 3.0],
    ...                [0.0, -1.0, 3.0]]])
    >>> b = u @ (0.5 * n[0])
    >>> b[0, 0] *= 3  # a highlight
    >>> fit_albedo_normals(b, u, n).round(6).tolist()
    [[0.0, 0.0, 0.5]]
    """
    out = np.full(start_normals.shape, np.nan)
    for lo in range(0, len(brightness), FIT_BLOCK):
        block = slice(lo, lo + FIT_BLOCK)
        b = brightness[block].astype(float)
        u = vectors[block].astype(float)
        seen = np.isfinite(b)
        b = np.where(seen, b, 0.0)
        use = seen & (np.einsum("vki,vi->vk", u, start_normals[block]) > 0)
        g, gram = _least_squares(b, u, use)
        for _ in range(REFITS):
            fitted = np.einsum("vki,vi->vk", u, g)
            use = seen & (fitted > 0) & (b <= HIGHLIGHT_FIT_RATIO * fitted)
            g, gram = _least_squares(b, u, use)
        spread = np.linalg.eigvalsh(gram)
        trusted = (use.sum(axis=1) >= MIN_FIT_VIEWS) & (spread[:, 0] > MIN_SPREAD * spread[:, 2])
        out[block][trusted] = g[trusted]
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
    """Each view's depth map with the pixels dropped (NaN) brighter than ``ratio`` times the
    brightest that the fitted albedo-normals (:func:`fit_albedo_normals`) of the face their
    ray meets on ``surface``, its corners' and their neighbours', predict in that view, and
    those within ``reach_px`` pixels of one, and how many pixels were dropped. ``images``
    (H, W, C) and ``masks`` are the views as PatchMatch matched them, at the depth maps'
    scale; ``light_offset`` is the lamp in the camera frame (metres); the fit starts from the
    surface's normals averaged over ``average_fraction`` of its longest side. Pixels whose ray
    misses ``surface``, that are lit at a grazing angle, or with a corner of their face that has
    no fit on or around it are kept."""
    radius = average_fraction * float(max(surface.extents))
    start = averaged_vertex_normals(surface, radius)
    faces = np.asarray(surface.faces)
    points = np.asarray(surface.vertices, dtype=float)
    caster = RayCaster(points, faces)
    albedo_normals = fit_albedo_normals(
        *view_readings(surface, start, images, masks, maps, poses, light_offset, caster), start)
    fitted = np.isfinite(albedo_normals[:, 0])
    unit = np.where(fitted[:, None], albedo_normals, start)
    face_normal = face_normals_of(surface, unit / np.linalg.norm(unit, axis=1, keepdims=True))
    edges = np.asarray(surface.edges_unique)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach_px + 1,) * 2)
    out: dict[int, ViewDepth] = {}
    dropped = 0
    for view, vd in maps.items():
        pose = poses[view]
        light = pose.light_position(light_offset)
        predicted = np.einsum("vi,vi->v", albedo_normals, lamp_vectors(points, light))
        # the brightest among the corners and their neighbours: beside an edge of the paint
        # a pixel and the fits there each mix the two paints in their own proportions
        nearby = predicted.copy()
        np.fmax.at(nearby, edges[:, 0], predicted[edges[:, 1]])
        np.fmax.at(nearby, edges[:, 1], predicted[edges[:, 0]])
        face_predicted = np.max(nearby[faces], axis=1)
        rows, cols, tri, hits = surface_hits(vd, pose, caster)
        s = shading(hits, face_normal[tri], light)
        bright = images[view].sum(axis=2)[rows, cols]
        with np.errstate(invalid="ignore"):
            over = (bright > ratio * face_predicted[tri]) & lit(s, hits, light)
        bright_mask = np.zeros(vd.distance.shape, np.uint8)
        bright_mask[rows[over], cols[over]] = 1
        dropped_here = cv2.dilate(bright_mask, kernel) if reach_px else bright_mask
        depth = np.where(dropped_here.astype(bool), np.nan, vd.distance)
        dropped += int(np.isfinite(vd.distance).sum() - np.isfinite(depth).sum())
        out[view] = replace(vd, distance=depth)
    return out, dropped
