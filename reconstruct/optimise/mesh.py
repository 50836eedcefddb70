"""Mesh operators the optimiser differentiates through: 1-ring adjacency, area-weighted vertex
normals and their exact Jacobian with respect to every vertex of the 1-ring.

The normal of vertex i is ``n_i = ñ_i / |ñ_i|`` with ``ñ_i = Σ_{f ∋ i} (x_b − x_a) × (x_c − x_a)``
(twice the area-weighted sum of the incident face normals). Its derivative is a sparse
(3N × 3N) matrix with one 3×3 block per (vertex, 1-ring vertex) pair; the optimiser chains the
shading and geometric-smoothness derivatives through it, so a normal depends on its neighbours
exactly as in the cost, not through a frozen approximation.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu

from reconstruct.optimise.kernels.normals import face_normal_sums, normal_jacobian_blocks


def adjacency(faces: np.ndarray, n_vertices: int) -> sp.csr_array:
    """Symmetric 0/1 vertex adjacency (N, N) of the triangle edges (no self loops)."""
    f = np.asarray(faces, dtype=np.int64)
    rows = np.concatenate([f[:, 0], f[:, 1], f[:, 2], f[:, 1], f[:, 2], f[:, 0]])
    cols = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 0], f[:, 1], f[:, 2]])
    a = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(n_vertices, n_vertices))
    a.data[:] = 1.0
    a.setdiag(0)
    a.eliminate_zeros()
    a.sort_indices()
    return a


def ring_mean(adj: sp.csr_array) -> sp.csr_array:
    """The operator taking vertex values to the mean over each vertex's 1-ring (N, N)."""
    degree = np.asarray(adj.sum(axis=1)).ravel()
    return sp.csr_array(sp.diags_array(1.0 / np.maximum(degree, 1.0)) @ adj)


def edges(adj: sp.csr_array) -> np.ndarray:
    """Unique undirected edges (E, 2) with i < j from an adjacency matrix."""
    upper = sp.triu(adj, k=1).tocoo()
    return np.stack([upper.row, upper.col], axis=1).astype(np.int64)


def unnormalised_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``ñ_i``: sum of the (twice-area) face normals around each vertex, (N, 3)."""
    x = np.ascontiguousarray(vertices, dtype=float)
    return face_normal_sums(x, np.ascontiguousarray(faces, dtype=np.int64))


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit area-weighted normals (N, 3) and the lengths ``|ñ_i|`` (isolated vertices: +z)."""
    raw = unnormalised_normals(vertices, faces)
    length = np.linalg.norm(raw, axis=1)
    safe = np.where(length > 0, length, 1.0)
    n = raw / safe[:, None]
    n[length == 0] = (0.0, 0.0, 1.0)
    return n, length


class NormalJacobian:
    """``∂n/∂X`` as a block-sparse (3N, 3N) matrix with 3×3 blocks (vertex i, ring vertex j).

    For a face (a, b, c) with ``N = (x_b − x_a) × (x_c − x_a)``:
    ``∂N/∂x_a = [x_c − x_b]_×``, ``∂N/∂x_b = [x_a − x_c]_×``, ``∂N/∂x_c = [x_b − x_a]_×``.
    ``[·]_×`` is linear, so the edge vectors are summed per (i, j) block first and crossed
    once; ``∂n/∂ñ = (I − n nᵀ)/|ñ|`` then gives ``([w]_× − n (n × w)ᵀ)/|ñ|``. The sparsity (the
    1-ring of every vertex plus an explicit diagonal block, zero for isolated vertices) depends
    only on the faces, so it is built once per mesh and shared by every evaluation.
    """

    def __init__(self, faces: np.ndarray, n_vertices: int):
        f = np.asarray(faces, dtype=np.int64)
        nv = int(n_vertices)
        rows = np.repeat(f, 3, axis=1).ravel()  # corner i (owner of the normal)
        cols = np.tile(f, (1, 3)).ravel()  # vertex j it depends on
        diag = np.arange(nv, dtype=np.int64) * (nv + 1)
        ukey, inverse = np.unique(np.r_[rows * nv + cols, diag], return_inverse=True)
        self.faces = f
        self.n_vertices = nv
        self.inverse = inverse[: rows.size]
        self.block_row = ukey // nv
        self.block_col = ukey % nv
        self.indptr = np.searchsorted(self.block_row, np.arange(nv + 1))
        self.n_blocks = int(ukey.size)
        self.diagonal_block = np.flatnonzero(self.block_row == self.block_col)  # D_ii, by i
        # The transpose's blocks, column by column (a product with ∂n/∂Xᵀ writes each row once).
        self.transpose_block = np.argsort(self.block_col, kind="stable")
        self.transpose_indptr = np.searchsorted(
            self.block_col[self.transpose_block], np.arange(nv + 1)
        )
        self.transpose_row = self.block_row[self.transpose_block]

    def __call__(
        self, vertices: np.ndarray, normals: tuple[np.ndarray, np.ndarray] | None = None
    ) -> sp.bsr_array:
        """∂n/∂X at ``vertices``; ``normals``: their :func:`vertex_normals`, if already known."""
        x = np.ascontiguousarray(vertices, dtype=float)
        n, length = vertex_normals(x, self.faces) if normals is None else normals
        inv = np.where(length > 0, 1.0 / np.where(length > 0, length, 1.0), 0.0)
        blocks = normal_jacobian_blocks(
            x, self.faces, self.inverse, self.n_blocks, self.block_row, n, inv
        )
        nv = self.n_vertices
        return sp.bsr_array(
            (blocks, self.block_col, self.indptr), shape=(3 * nv, 3 * nv), blocksize=(3, 3)
        )


def normal_jacobian(vertices: np.ndarray, faces: np.ndarray) -> sp.bsr_array:
    """``∂n/∂X`` (see :class:`NormalJacobian`; build that once to evaluate it repeatedly)."""
    return NormalJacobian(faces, len(vertices))(vertices)


def boundary_vertices(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """True for the vertices on an edge that only one face uses (N,)."""
    f = np.asarray(faces, dtype=np.int64)
    a, b = f.ravel(), f[:, [1, 2, 0]].ravel()
    # an edge as one integer, as in reconstruct.initial_mesh.repair: a 1-D unique is fast
    key, count = np.unique(np.minimum(a, b) * n_vertices + np.maximum(a, b), return_counts=True)
    once = key[count == 1]
    on_boundary = np.zeros(n_vertices, dtype=bool)
    on_boundary[once // n_vertices] = True
    on_boundary[once % n_vertices] = True
    return on_boundary


def relax_tangentially(
    vertices: np.ndarray,
    faces: np.ndarray,
    movable: np.ndarray | None = None,
    iterations: int = 5,
    step: float = 0.5,
) -> np.ndarray:
    """Vertices moved towards their 1-ring centroids within their tangent planes.

    Moving each vertex along its own normal (as the joint stages do) leaves the triangles
    uneven and folds slivers over; the data term is blind to motion along the surface, so
    evening it out keeps the shape and unfolds them. Only ``movable`` vertices (all, if None)
    off the boundary move.
    """
    X = np.array(vertices, dtype=float)
    n = len(X)
    adj = adjacency(faces, n)
    centroid = ring_mean(adj)
    free = (np.diff(adj.indptr) > 0) & ~boundary_vertices(faces, n)  # has neighbours, no rim
    if movable is not None:
        free &= movable
    for _ in range(iterations):
        normals, _ = vertex_normals(X, faces)
        towards = centroid @ X - X
        towards -= np.einsum("ij,ij->i", towards, normals)[:, None] * normals
        X[free] += step * towards[free]
    return X


def carried_along(
    displacement: np.ndarray, faces: np.ndarray, moved: np.ndarray
) -> np.ndarray:
    """``displacement`` (N, 3) with the rows of the vertices not ``moved`` replaced by the
    harmonic extension of the moved ones' (each the mean of its 1-ring's).

    A vertex without enough views to move on its own is still part of the surface around it:
    where a blob of the initial mesh turned its normals away from most views, its middle sees
    too few to move while its rim follows the data, and left behind it stays a pit. Vertices
    in a part of the mesh with no moved vertex keep their own displacement.

    >>> faces = np.array([[0, 1, 2], [1, 3, 2]])
    >>> d = np.array([[0.0, 0, 1], [0, 0, 1], [0, 0, 0], [0, 0, 1]])
    >>> carried_along(d, faces, np.array([True, True, False, True]))[2].tolist()
    [0.0, 0.0, 1.0]
    """
    d = np.array(displacement, dtype=float)
    held = np.flatnonzero(~moved)
    if held.size == 0 or not moved.any():
        return d
    adj = adjacency(faces, len(d))
    rows = adj[held]
    inner, to_moved = rows[:, held], rows[:, moved]
    # only held parts that touch a moved vertex are solved for (elsewhere the Laplacian is
    # singular)
    n_parts, part = connected_components(inner, directed=False)
    touching = np.zeros(n_parts, dtype=bool)
    touching[part[to_moved.sum(axis=1) > 0]] = True
    solve = touching[part]
    if not solve.any():
        return d
    degree = np.asarray(rows.sum(axis=1)).ravel()[solve]
    laplacian = sp.diags_array(degree) - inner[solve][:, solve]
    d[held[solve]] = splu(sp.csc_array(laplacian)).solve(to_moved[solve] @ d[moved])
    return d
