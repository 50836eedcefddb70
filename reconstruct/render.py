"""Image rendering with the one forward model (:mod:`reconstruct.forward`).

Rendering is split in two so several illuminations from one pose cost little:

1. :func:`trace_view` casts one primary ray per sub-pixel (COLMAP pixel convention, pixel
   centres at +0.5) and keeps, for every sub-pixel that hits the mesh, the hit triangle's
   vertices, barycentrics, point and shading normal.
2. :func:`light_weight` (a point light: bulb) or :func:`projector_weights` (a projector: a near
   point light whose colour per ray is the projector pixel the point projects to) computes the
   wavelength-independent factor ``m · s`` per hit once per light position.
3. :func:`shade` turns those into a linear image for any spectra: per-vertex RGB
   ``(C^T L) r`` interpolated with the barycentrics (exactly the barycentric interpolation of
   the reflectance, since the model is linear in r), times ``m · s``, box-filtered to pixels.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from calibration.errors import RigError
from reconstruct import forward
from reconstruct.camera import Intrinsics, Pose, project
from reconstruct.raycast import RayCaster

NormalMode = Literal["smooth", "flat"]


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit geometric normals of the triangles (F, 3) (counter-clockwise = outward)."""
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (V, 3): the smooth normals the paper's ``n(x_i)``
    computes from a vertex and its neighbours."""
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 * area
    out = np.zeros_like(vertices, dtype=float)
    for k in range(3):
        np.add.at(out, faces[:, k], n)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)


@dataclass(frozen=True)
class ViewHits:
    """Primary-ray hits of one camera pose, on a ``(H·ss) × (W·ss)`` sub-pixel grid."""

    height: int
    width: int
    supersample: int
    index: np.ndarray  # (K,) flat sub-pixel index of each hit
    vertex_index: np.ndarray  # (K, 3) the hit triangle's vertices
    barycentric: np.ndarray  # (K, 3)
    points: np.ndarray  # (K, 3) world hit points
    normals: np.ndarray  # (K, 3) unit shading normals
    face_normals: np.ndarray  # (K, 3) unit geometric normals (for shadow-ray offsets)

    def coverage(self) -> np.ndarray:
        """Fraction of each pixel's sub-samples that hit the mesh, (H, W) in [0, 1]."""
        return self.box_filter(np.ones((len(self.index), 1)))[..., 0]

    def box_filter(self, values: np.ndarray) -> np.ndarray:
        """Per-hit values (K, c) -> (H, W, c): the mean over each pixel's ss² sub-samples
        (misses count as 0), i.e. a box filter, which is the anti-aliasing."""
        ss = self.supersample
        row, col = np.divmod(self.index, self.width * ss)
        pixel = (row // ss) * self.width + col // ss
        n = self.height * self.width
        out = np.stack(
            [np.bincount(pixel, values[:, k], minlength=n) for k in range(values.shape[1])],
            axis=1,
        )
        return out.reshape(self.height, self.width, -1) / ss**2


def _pixel_window(intrinsics: Intrinsics, pose: Pose, vertices: np.ndarray) -> tuple[slice, slice]:
    """Rows/cols the mesh can cover (the projection of its bounding box), so rays that must
    miss are never cast. The whole image when part of the mesh is behind the camera."""
    full = (slice(0, intrinsics.height), slice(0, intrinsics.width))
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    corners = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    uv = project(intrinsics, pose, corners)  # the box's projection bounds the mesh's
    if not np.isfinite(uv).all():
        return full
    lo = np.floor(uv.min(axis=0)).astype(int) - 1
    hi = np.ceil(uv.max(axis=0)).astype(int) + 1
    c0, r0 = np.maximum(lo, 0)
    c1, r1 = np.minimum(hi, [intrinsics.width, intrinsics.height])
    if c1 <= c0 or r1 <= r0:
        return slice(0, 0), slice(0, 0)
    return slice(int(r0), int(r1)), slice(int(c0), int(c1))


def trace_view(
    caster: RayCaster,
    intrinsics: Intrinsics,
    pose: Pose,
    supersample: int = 2,
    normals: NormalMode = "smooth",
    smooth_normals: np.ndarray | None = None,
) -> ViewHits:
    """Cast one ray per sub-pixel through the camera and record what each one hits.

    ``normals="smooth"`` interpolates vertex normals with the barycentrics (pass precomputed
    ``smooth_normals`` to avoid recomputing them per view), ``"flat"`` uses face normals.
    """
    if supersample < 1:
        raise RigError(f"supersample={supersample}", "use a whole number >= 1")
    if normals not in ("smooth", "flat"):
        raise RigError(f"normal mode {normals!r} is unknown", "use 'smooth' or 'flat'")
    ss = supersample
    W = intrinsics.width * ss
    rows, cols = _pixel_window(intrinsics, pose, caster.vertices)
    sr = np.arange(rows.start * ss, rows.stop * ss)
    sc = np.arange(cols.start * ss, cols.stop * ss)
    grid_r, grid_c = np.meshgrid(sr, sc, indexing="ij")
    flat = (grid_r * W + grid_c).ravel()
    uv = np.stack([(grid_c.ravel() + 0.5) / ss, (grid_r.ravel() + 0.5) / ss], axis=1)
    dirs = intrinsics.pixel_rays(uv) @ pose.R  # camera -> world: R^T d
    tri, dist, bary = caster.first_hit(np.broadcast_to(pose.center, dirs.shape), dirs)
    hit = tri >= 0
    tri, bary = tri[hit], bary[hit]
    vidx = caster.faces[tri]
    points = pose.center + dist[hit, None] * dirs[hit]
    fn = face_normals(caster.vertices, caster.faces[tri])
    if normals == "smooth":
        vn = smooth_normals
        if vn is None:
            vn = vertex_normals(caster.vertices, caster.faces)
        sn = np.einsum("kj,kjd->kd", bary, vn[vidx])
        sn /= np.maximum(np.linalg.norm(sn, axis=1, keepdims=True), 1e-300)
    else:
        sn = fn
    return ViewHits(intrinsics.height, intrinsics.width, ss, flat[hit], vidx, bary, points, sn, fn)


def light_weight(caster: RayCaster, hits: ViewHits, light_position: np.ndarray) -> np.ndarray:
    """``m · s`` per hit for a point light at ``light_position`` (world, metres), (K,)."""
    s = forward.shading(hits.points, hits.normals, light_position)
    lit = s > 0
    m = np.zeros(len(s), dtype=bool)
    m[lit] = ~caster.occluded(hits.points[lit], light_position, normals=hits.face_normals[lit])
    return s * m


def projector_weights(
    caster: RayCaster,
    hits: ViewHits,
    image: np.ndarray,
    intrinsics: Intrinsics,
    pose: Pose,
) -> np.ndarray:
    """``m · s · I_k`` per hit for a projector, (K, 3): one weight per projector primary k.

    The projector is a near point light at its optical centre whose emitted colour along each
    ray is the pixel of ``image`` ((h, w) or (h, w, 3); float in [0, 1] or uint8, linear) that
    the surface point projects to (nearest pixel: projector pixels are little squares).
    Points outside the projector's frame get no light.
    """
    img = _as_float_image(image, intrinsics)
    w = light_weight(caster, hits, pose.center)
    uv = project(intrinsics, pose, hits.points)
    inside = intrinsics.in_image(uv) & (w > 0)
    col = np.clip(np.floor(uv[inside, 0]).astype(int), 0, intrinsics.width - 1)
    row = np.clip(np.floor(uv[inside, 1]).astype(int), 0, intrinsics.height - 1)
    out = np.zeros((len(w), 3))
    out[inside] = img[row, col] * w[inside, None]
    return out


def _as_float_image(image: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    img = np.asarray(image)
    if img.shape[:2] != (intrinsics.height, intrinsics.width) or img.ndim not in (2, 3):
        raise RigError(
            f"projector image has shape {img.shape}, the projector is "
            f"{intrinsics.width}x{intrinsics.height}",
            "pass an (H, W) or (H, W, 3) image of the projector's size",
        )
    img = img.astype(float) / 255.0 if img.dtype == np.uint8 else img.astype(float)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    return np.clip(img[..., :3], 0.0, 1.0)


def shade(
    hits: ViewHits,
    terms: Sequence[tuple[np.ndarray, np.ndarray]],
    vertex_reflectance: np.ndarray,
) -> np.ndarray:
    """Linear image (H, W, 3) from ``(weight (K,), response (3, N_λ))`` terms, summed.

    A bulb is one term ``(light_weight, C^T diag(L))``; a projector is three, one per primary
    with its SPD. Sub-pixels are averaged per pixel (box filter = anti-aliasing).
    """
    R = np.asarray(vertex_reflectance, dtype=float)
    return shade_vertex_rgb(hits, [(w, vertex_rgb(R, resp)) for w, resp in terms])


def vertex_rgb(vertex_reflectance: np.ndarray, response: np.ndarray) -> np.ndarray:
    """``(C^T L) r`` per vertex at unit shading, (V, 3); cache it per illumination."""
    R = np.asarray(vertex_reflectance, dtype=float)
    return forward.render_values(R, np.ones(len(R)), response)


def shade_vertex_rgb(hits: ViewHits, terms: Sequence[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """As :func:`shade` with precomputed :func:`vertex_rgb` ``(weight (K,), rgb (V, 3))``."""
    y = np.zeros((len(hits.index), 3))
    for weight, vrgb in terms:
        y += weight[:, None] * np.einsum("kj,kjc->kc", hits.barycentric, vrgb[hits.vertex_index])
    return hits.box_filter(y)


def render_image(
    vertices: np.ndarray,
    faces: np.ndarray,
    vertex_reflectance: np.ndarray,
    intrinsics: Intrinsics,
    pose: Pose,
    light_position: np.ndarray,
    response: np.ndarray,
    supersample: int = 2,
    normals: NormalMode = "smooth",
    caster: RayCaster | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One view lit by one point light: linear image (H, W, 3) and coverage (H, W) in [0, 1].

    ``response`` is ``C^T diag(L)`` (3, N_λ) from :func:`reconstruct.forward.response_matrix`.
    """
    rc = caster or RayCaster(vertices, faces)
    hits = trace_view(rc, intrinsics, pose, supersample, normals)
    w = light_weight(rc, hits, np.asarray(light_position, dtype=float))
    return shade(hits, [(w, response)], vertex_reflectance), hits.coverage()


def render_projector_image(
    vertices: np.ndarray,
    faces: np.ndarray,
    vertex_reflectance: np.ndarray,
    intrinsics: Intrinsics,
    pose: Pose,
    projector_image: np.ndarray,
    projector_intrinsics: Intrinsics,
    projector_pose: Pose,
    primary_responses: Sequence[np.ndarray],
    supersample: int = 2,
    normals: NormalMode = "smooth",
    caster: RayCaster | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One view lit by a projector showing ``projector_image``.

    ``primary_responses`` are ``C^T diag(L_k)`` for the projector's R, G, B primaries.
    """
    if len(primary_responses) != 3:
        raise RigError(
            f"{len(primary_responses)} projector primary responses given",
            "pass three (R, G, B primary SPDs through response_matrix)",
        )
    rc = caster or RayCaster(vertices, faces)
    hits = trace_view(rc, intrinsics, pose, supersample, normals)
    w = projector_weights(rc, hits, projector_image, projector_intrinsics, projector_pose)
    terms = [(w[:, k], primary_responses[k]) for k in range(3)]
    return shade(hits, terms, vertex_reflectance), hits.coverage()
