"""Flat test meshes: sampled rectangles (plates, walls) and meshes joined part by part."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def rectangle(
    corner: Sequence[float], edge_a: Sequence[float], edge_b: Sequence[float], n: int
) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle sampled n x n (vertices, faces), its normal along edge_a x edge_b."""
    a, b = (t.ravel()[:, None] for t in np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n)))
    vertices = np.asarray(corner) + a * np.asarray(edge_a) + b * np.asarray(edge_b)
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    faces = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    return vertices, faces


def join(*parts: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Meshes joined: (vertices, faces, the part index k of every vertex)."""
    vertices, faces, part, offset = [], [], [], 0
    for k, (v, f) in enumerate(parts):
        vertices.append(v)
        faces.append(f + offset)
        part.append(np.full(len(v), k))
        offset += len(v)
    return np.concatenate(vertices), np.concatenate(faces), np.concatenate(part)
