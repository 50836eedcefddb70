"""Image rendering with the one forward model (:mod:`reconstruct.model.forward`).

Rendering is split in two so several illuminations from one pose cost little:

1. :func:`trace_view` casts one primary ray per sub-pixel (COLMAP pixel convention, pixel
   centres at +0.5) and keeps, for every sub-pixel that hits the mesh, the hit triangle's
   vertices, barycentrics, point and shading normal.
2. :func:`light_weight` (a point light, or a bulb with a size: bulb) or
   :func:`projector_weights` (a projector: a near point light whose colour per ray is the
   projector pixel the point projects to) computes the wavelength-independent factor ``m · s``
   per hit once per light position; :func:`specular_weight` a neutral gloss lobe's.
3. :func:`shade` turns those into a linear image for any spectra: per-vertex RGB
   ``(C^T L) r`` interpolated with the barycentrics (exactly the barycentric interpolation of
   the reflectance, since the model is linear in r), times ``m · s``, box-filtered to pixels.

An optional :class:`GroundPlane` (a printed board under the object) is traced analytically:
its hits join the mesh hits as two virtual vertices past the mesh's, "paper" and "ink",
blended with the bilinearly sampled texture as barycentrics, so shading, shadows (the
object's shadow falls on the plane) and projector light need no special case.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from core.errors import RigError
from reconstruct.model import bulb, forward
from reconstruct.model.camera import Intrinsics, Pose, project
from reconstruct.model.raycast import RayCaster

NormalMode = Literal["smooth", "flat"]
BULB_SAMPLES = 16  # directions to a sized bulb per hit (even: they come in opposite pairs)


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
class GroundPlane:
    """A textured flat quad in the plane z = 0 facing +z (world frame, metres).

    ``texture`` (H, W) in [0, 1] blends ``paper`` (1) and ``ink`` (0) reflectances (N_λ,);
    row 0 is the edge y = y1, column 0 the edge x = x0 of ``extent`` = (x0, y0, x1, y1), each
    texel a little square, sampled bilinearly between texel centres.
    """

    texture: np.ndarray
    extent: tuple[float, float, float, float]
    paper: np.ndarray
    ink: np.ndarray

    def __post_init__(self) -> None:
        tex = np.asarray(self.texture)
        x0, y0, x1, y1 = self.extent
        if tex.ndim != 2 or min(tex.shape) < 2 or not (x1 > x0 and y1 > y0):
            raise RigError(
                f"ground texture of shape {tex.shape} with extent {self.extent}",
                "give an (H, W) image of at least 2x2 and an extent (x0, y0, x1, y1) with "
                "x1 > x0 and y1 > y0 (metres)",
            )
        if np.shape(self.paper) != np.shape(self.ink) or np.ndim(self.paper) != 1:
            raise RigError(
                f"ground paper/ink reflectances have shapes {np.shape(self.paper)} and "
                f"{np.shape(self.ink)}",
                "give two spectra on the scene's wavelength grid",
            )

    def corners(self) -> np.ndarray:
        """The quad's four corners (4, 3)."""
        x0, y0, x1, y1 = self.extent
        return np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])

    def intersect(self, origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Distance along each ray (unit ``directions`` (N, 3)) to the quad, inf on a miss."""
        dz = directions[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -origin[2] / dz
        x = origin[0] + t * directions[:, 0]
        y = origin[1] + t * directions[:, 1]
        x0, y0, x1, y1 = self.extent
        hit = (t > 0) & (dz != 0) & (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        return np.where(hit, t, np.inf)

    def sample(self, xy: np.ndarray) -> np.ndarray:
        """Bilinear texture value at world points ``xy`` (N, 2) on the quad, (N,)."""
        tex = np.asarray(self.texture)
        h, w = tex.shape
        x0, y0, x1, y1 = self.extent
        u = np.clip((xy[:, 0] - x0) * (w / (x1 - x0)) - 0.5, 0.0, w - 1.0)
        v = np.clip((y1 - xy[:, 1]) * (h / (y1 - y0)) - 0.5, 0.0, h - 1.0)
        c = np.minimum(np.floor(u).astype(np.int64), w - 2)
        r = np.minimum(np.floor(v).astype(np.int64), h - 2)
        fu, fv = u - c, v - r
        top = tex[r, c] * (1 - fu) + tex[r, c + 1] * fu
        bottom = tex[r + 1, c] * (1 - fu) + tex[r + 1, c + 1] * fu
        return np.asarray(top * (1 - fv) + bottom * fv, dtype=float)


def with_ground(vertex_reflectance: np.ndarray, ground: GroundPlane | None) -> np.ndarray:
    """Per-vertex reflectance (V, N_λ) extended by the ground's paper and ink rows (the two
    virtual vertices :func:`trace_view` gives ground hits)."""
    R = np.asarray(vertex_reflectance, dtype=float)
    if ground is None:
        return R
    return np.vstack([R, np.asarray(ground.paper, float), np.asarray(ground.ink, float)])


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
    on_ground: np.ndarray | None = None  # (K,) bool: the hit is on the ground plane

    def coverage(self) -> np.ndarray:
        """Fraction of each pixel's sub-samples that hit the mesh (not the ground), (H, W)."""
        mesh = np.ones(len(self.index)) if self.on_ground is None else ~self.on_ground
        return self.box_filter(mesh[:, None].astype(float))[..., 0]

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
    """Rows/cols the points can cover (the projection of their bounding box), so rays that
    must miss are never cast. The whole image when part of the box is behind the camera."""
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
    ground: GroundPlane | None = None,
) -> ViewHits:
    """Cast one ray per sub-pixel through the camera and record what each one hits.

    ``normals="smooth"`` interpolates vertex normals with the barycentrics (pass precomputed
    ``smooth_normals`` to avoid recomputing them per view), ``"flat"`` uses face normals.
    With a ``ground`` plane, rays reaching it before the mesh hit it (vertex indices V and
    V + 1, see :func:`with_ground`); shade such hits with :func:`with_ground` reflectances.
    """
    if supersample < 1:
        raise RigError(f"supersample={supersample}", "use a whole number >= 1")
    if normals not in ("smooth", "flat"):
        raise RigError(f"normal mode {normals!r} is unknown", "use 'smooth' or 'flat'")
    ss = supersample
    W = intrinsics.width * ss
    extent = caster.vertices if ground is None else np.vstack([caster.vertices, ground.corners()])
    rows, cols = _pixel_window(intrinsics, pose, extent)
    sr = np.arange(rows.start * ss, rows.stop * ss)
    sc = np.arange(cols.start * ss, cols.stop * ss)
    grid_r, grid_c = np.meshgrid(sr, sc, indexing="ij")
    flat = (grid_r * W + grid_c).ravel()
    uv = np.stack([(grid_c.ravel() + 0.5) / ss, (grid_r.ravel() + 0.5) / ss], axis=1)
    dirs = intrinsics.pixel_rays(uv) @ pose.R  # camera -> world: R^T d
    # Only rays inside the mesh's own window can hit it; the rest of a ground's window
    # meets the plane alone.
    mr, mc = (
        _pixel_window(intrinsics, pose, caster.vertices) if ground is not None else (rows, cols)
    )
    near = (
        (grid_r.ravel() >= mr.start * ss)
        & (grid_r.ravel() < mr.stop * ss)
        & (grid_c.ravel() >= mc.start * ss)
        & (grid_c.ravel() < mc.stop * ss)
    )
    tri = np.full(len(dirs), -1, dtype=np.int64)
    dist = np.full(len(dirs), np.inf)
    bary = np.zeros((len(dirs), 3))
    tri[near], dist[near], bary[near] = caster.first_hit(
        np.broadcast_to(pose.center, (int(near.sum()), 3)), dirs[near]
    )
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
    if ground is None:
        return ViewHits(
            intrinsics.height, intrinsics.width, ss, flat[hit], vidx, bary, points, sn, fn
        )
    t = ground.intersect(pose.center, dirs)
    on = np.isfinite(t) & (t < dist)  # the mesh wins ties (a card lying on the plane)
    mesh_hit = hit & ~on
    keep = mesh_hit[hit]
    gp = pose.center + t[on, None] * dirs[on]
    paper = ground.sample(gp[:, :2])
    n_v = len(caster.vertices)
    up = np.broadcast_to([0.0, 0.0, 1.0], gp.shape)
    return ViewHits(
        intrinsics.height,
        intrinsics.width,
        ss,
        np.concatenate([flat[mesh_hit], flat[on]]),
        np.concatenate([vidx[keep], np.broadcast_to([n_v, n_v + 1, n_v], gp.shape)]),
        np.concatenate([bary[keep], np.stack([paper, 1 - paper, np.zeros_like(paper)], 1)]),
        np.concatenate([points[keep], gp]),
        np.concatenate([sn[keep], up]),
        np.concatenate([fn[keep], up]),
        np.concatenate([np.zeros(int(keep.sum()), bool), np.ones(len(gp), bool)]),
    )


def light_weight(
    caster: RayCaster, hits: ViewHits, light_position: np.ndarray, radius: float = 0.0
) -> np.ndarray:
    """``m · s`` per hit for a point light at ``light_position`` (world, metres), (K,); with a
    ``radius``, for a spherical bulb there: :data:`BULB_SAMPLES` directions over the cone it
    subtends from each hit (:func:`reconstruct.model.bulb.cone_samples`), each with its own
    cosine and shadow ray — soft shadow edges, and a bulb across the horizon lit in part."""
    centre = np.asarray(light_position, dtype=float)
    if radius <= 0:
        s = forward.shading(hits.points, hits.normals, centre)
        return s * _unoccluded(caster, hits, np.broadcast_to(centre, hits.points.shape), s > 0)
    targets, scale = bulb.cone_samples(hits.points, centre, radius, BULB_SAMPLES)
    total = np.zeros(len(hits.index))
    for target in targets:
        ray = target - hits.points
        cos = np.einsum("ij,ij->i", hits.normals, ray) / np.linalg.norm(ray, axis=1)
        total += np.maximum(cos, 0.0) * _unoccluded(caster, hits, target, cos > 0)
    return total * scale


def _unoccluded(
    caster: RayCaster, hits: ViewHits, targets: np.ndarray, lit: np.ndarray
) -> np.ndarray:
    """Whether each ``lit`` hit sees its target (K, 3): false where not ``lit``."""
    # Only a segment meeting the mesh's bounding box can be blocked: the rest (most ground
    # hits) need no shadow ray.
    test = lit.copy()
    test[lit] = _segment_meets_box(
        hits.points[lit], targets[lit], caster.vertices.min(0), caster.vertices.max(0)
    )
    clear = lit & ~test
    clear[test] = ~caster.occluded(
        hits.points[test], targets[test], normals=hits.face_normals[test]
    )
    return clear


def specular_weight(
    hits: ViewHits,
    light_position: np.ndarray,
    camera_centre: np.ndarray,
    lit: np.ndarray,
    specular: float,
    alpha: float,
) -> np.ndarray:
    """A neutral GGX lobe's weight per hit (K,) (:func:`forward.ggx_lobe`), ``lit`` the light's
    ``m · s``: with the white reflectance's RGB it is the highlight in the lamp's own colour
    (dichromatic model)."""
    to_light = np.asarray(light_position, dtype=float) - hits.points
    to_eye = np.asarray(camera_centre, dtype=float) - hits.points
    to_light /= np.linalg.norm(to_light, axis=1, keepdims=True)
    to_eye /= np.linalg.norm(to_eye, axis=1, keepdims=True)
    cos_l = np.einsum("ij,ij->i", hits.normals, to_light)
    lobe = forward.ggx_lobe(hits.normals, to_light, to_eye, alpha, specular)
    return np.where(cos_l > 0, lobe * lit / np.maximum(cos_l, 1e-12), 0.0)


def _segment_meets_box(
    points: np.ndarray, end: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """Which segments ``points`` (N, 3) -> ``end`` (3,) touch the box [lo, hi] (slab test,
    padded by a relative 1e-6 so grazing segments are still ray-tested)."""
    pad = 1e-6 * max(float(np.max(hi - lo)), 1e-9)
    d = np.asarray(end, dtype=float) - points
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (lo - pad - points) / d
        t1 = (hi + pad - points) / d
    near = np.where(np.isnan(t0), -np.inf, np.minimum(t0, t1))
    far = np.where(np.isnan(t1), np.inf, np.maximum(t0, t1))
    # a zero component: inside that slab (all t) or outside it (none)
    flat = d == 0
    inside = (points >= lo - pad) & (points <= hi + pad)
    near = np.where(flat, np.where(inside, -np.inf, np.inf), near)
    far = np.where(flat, np.where(inside, np.inf, -np.inf), far)
    enter = np.maximum(near.max(axis=1), 0.0)
    leave = np.minimum(far.min(axis=1), 1.0)
    return np.asarray(enter <= leave)


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
    ground: GroundPlane | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One view lit by one point light: linear image (H, W, 3) and the mesh's coverage
    (H, W) in [0, 1], optionally standing on a textured ``ground`` plane.

    ``response`` is ``C^T diag(L)`` (3, N_λ) from :func:`reconstruct.model.forward.response_matrix`.
    """
    rc = caster or RayCaster(vertices, faces)
    hits = trace_view(rc, intrinsics, pose, supersample, normals, ground=ground)
    w = light_weight(rc, hits, np.asarray(light_position, dtype=float))
    refl = with_ground(vertex_reflectance, ground)
    return shade(hits, [(w, response)], refl), hits.coverage()
