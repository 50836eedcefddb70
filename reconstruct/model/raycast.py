"""Ray casting against a triangle mesh with Embree (through trimesh + embreex).

One caster serves the renderer (primary rays, shadow rays), the visibility stage (vertex ->
camera centre) and the optimiser's shadow masks (vertex -> light). Embree finds *which*
triangle a ray hits in float32; distance and barycentrics are then recomputed in float64 on that
triangle (Möller–Trumbore), so hit points lie on the mesh to double precision.
"""

from __future__ import annotations

import numpy as np
import trimesh
import trimesh.ray

from core.errors import RigError

# A hit closer than this (relative to the scene size) to a ray's origin is the surface the ray
# started on, not an occluder; such rays are re-cast from just past it.
_SELF_HIT_PASSES = 3


class RayCaster:
    """First-hit and segment-occlusion queries on one mesh (vertices (V, 3), faces (F, 3))."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        if not trimesh.ray.has_embree:
            raise RigError(
                "Embree ray casting is not available (trimesh cannot import embreex)",
                "install it with `pip install embreex` (it ships with spectral-rig's dependencies)",
            )
        from trimesh.ray.ray_pyembree import RayMeshIntersector

        v = np.asarray(vertices, dtype=float)
        f = np.asarray(faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
            raise RigError(
                f"mesh arrays have shapes {v.shape} and {f.shape}",
                "pass vertices (V, 3) and triangle faces (F, 3) with at least one face",
            )
        self.vertices = v
        self.faces = f
        self._tri = v[f]  # (F, 3, 3)
        mesh = trimesh.Trimesh(vertices=v, faces=f, process=False, validate=False)
        self.scale = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))) or 1.0
        self._intersector = RayMeshIntersector(mesh)

    def _solve(
        self, tri: np.ndarray, origins: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Möller–Trumbore on given triangles: distance along unit rays and barycentrics."""
        a, b, c = self._tri[tri, 0], self._tri[tri, 1], self._tri[tri, 2]
        e1, e2 = b - a, c - a
        pvec = np.cross(directions, e2)
        det = np.einsum("ij,ij->i", e1, pvec)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tvec = origins - a
            u = np.einsum("ij,ij->i", tvec, pvec) * inv
            qvec = np.cross(tvec, e1)
            v = np.einsum("ij,ij->i", directions, qvec) * inv
            t = np.einsum("ij,ij->i", e2, qvec) * inv
        bary = np.clip(np.stack([1.0 - u - v, u, v], axis=1), 0.0, 1.0)
        bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
        return t, bary

    def first_hit(
        self, origins: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First triangle hit by each ray.

        Returns ``tri`` (N,) int (-1 = miss), ``distance`` (N,) along the *unit* direction
        (inf on a miss) and ``barycentric`` (N, 3) weights of the triangle's three vertices
        (zeros on a miss).
        """
        o = np.atleast_2d(np.asarray(origins, dtype=float))
        d = np.atleast_2d(np.asarray(directions, dtype=float))
        o, d = np.broadcast_arrays(o, d)
        norm = np.linalg.norm(d, axis=1, keepdims=True)
        d = d / np.where(norm > 0, norm, 1.0)
        n = len(o)
        tri = np.full(n, -1, dtype=np.int64)
        dist = np.full(n, np.inf)
        bary = np.zeros((n, 3))
        if n == 0:
            return tri, dist, bary
        hit = np.asarray(self._intersector.intersects_first(o, d), dtype=np.int64)
        idx = np.flatnonzero(hit >= 0)
        t, b = self._solve(hit[idx], o[idx], d[idx])
        tri[idx], dist[idx], bary[idx] = hit[idx], t, b
        return tri, dist, bary

    def occluded(
        self,
        points: np.ndarray,
        targets: np.ndarray,
        eps: float = 1e-6,
        normals: np.ndarray | None = None,
    ) -> np.ndarray:
        """Whether the segment from each point to its target crosses the mesh, (N,) bool.

        ``targets`` is (3,) or (N, 3): the light for shadow masks, the camera centre for
        visibility. ``eps`` (relative to the scene's bounding-box diagonal) is skipped at both
        ends so the surface a point lies on does not occlude it. With ``normals`` the start is
        also lifted off the surface along the normal side facing the target (avoids shadow acne
        at grazing angles).
        """
        p = np.atleast_2d(np.asarray(points, dtype=float))
        q = np.broadcast_to(np.asarray(targets, dtype=float), p.shape)
        tol = eps * self.scale
        seg = q - p
        length = np.linalg.norm(seg, axis=1)
        d = seg / np.where(length > 0, length, 1.0)[:, None]
        start = p.copy()
        if normals is not None:
            nrm = np.asarray(normals, dtype=float)
            side = np.sign(np.einsum("ij,ij->i", nrm, d))
            start += (tol * side)[:, None] * nrm
        start += tol * d
        remaining = length - tol
        blocked = np.zeros(len(p), dtype=bool)
        todo = np.flatnonzero(remaining > tol)
        for _ in range(_SELF_HIT_PASSES):
            if todo.size == 0:
                break
            tri, dist, _ = self.first_hit(start[todo], d[todo])
            hit = tri >= 0
            self_hit = hit & (dist <= tol)
            blocked[todo[hit & ~self_hit & (dist < remaining[todo] - tol)]] = True
            # Re-cast rays that only hit the surface they started on, from just past it.
            again = todo[self_hit]
            step = np.maximum(dist[self_hit], 0.0) + tol
            start[again] += step[:, None] * d[again]
            remaining[again] -= step
            todo = again[remaining[again] > tol]
        return blocked
