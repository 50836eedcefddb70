"""The data of one joint solve: frames, rig, observation list, regulariser weights, and the
layout of the parameter vector θ = [X (3N), A (N·N_b), light (3 or 3·N_views)].

Observations are (vertex, frame) pairs, sorted by (vertex, view, frame) so the frames of one
(vertex, view) pair are a contiguous run sharing that pair's geometry. Which observations exist
(visible, inside the image, unsaturated, lit) and the weights that depend on the current
estimate (photometric weights, geometric scale) are fixed for one solve and rebuilt between the
outer iterations of the paper's optimisation steps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from calibration.prior import SpectralRegulariser
from core.errors import RigError
from reconstruct.model.camera import Intrinsics, Pose

LightMode = Literal["offset", "free"]


@dataclass
class Frames:
    """Captured frames: which view (pose) and illumination each is, and optionally the linear
    images (F, H, W, 3) with their validity masks (F, H, W) (False = saturated/unusable) and a
    relative noise weight per frame (F,) — 1/std relative to a frame with no ambient
    subtracted (:mod:`reconstruct.frames.ambient`); None: all 1."""

    view: np.ndarray
    illumination: np.ndarray
    images: np.ndarray | None = None
    valid: np.ndarray | None = None
    weight: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.view = np.asarray(self.view, dtype=np.int64)
        self.illumination = np.asarray(self.illumination, dtype=np.int64)
        if self.images is not None and self.valid is None:
            self.valid = np.ones(self.images.shape[:3], dtype=bool)

    @property
    def count(self) -> int:
        return int(self.view.size)


@dataclass
class Rig:
    """Per-view cameras and poses and the response matrices ``C^T diag(L_k)`` (K, 3, N_λ)."""

    intrinsics: list[Intrinsics]
    poses: list[Pose]
    responses: np.ndarray

    @property
    def n_views(self) -> int:
        return len(self.poses)


@dataclass
class Observations:
    """(vertex, frame) pairs, sorted by (vertex, view, frame); ``fixed_rgb`` (M, 3) replaces
    image sampling when observations are given directly (no disparity cue)."""

    vertex: np.ndarray
    frame: np.ndarray
    view: np.ndarray
    illumination: np.ndarray
    fixed_rgb: np.ndarray | None = None
    pair_start: np.ndarray = field(init=False)
    per_vertex: np.ndarray = field(init=False)

    @classmethod
    def build(
        cls,
        vertex: np.ndarray,
        frame: np.ndarray,
        frames: Frames,
        n_vertices: int,
        fixed_rgb: np.ndarray | None = None,
    ) -> Observations:
        vertex = np.asarray(vertex, dtype=np.int64)
        frame = np.asarray(frame, dtype=np.int64)
        view = frames.view[frame]
        order = np.lexsort((frame, view, vertex))
        # int32 indices: four per observation, so half the memory; arithmetic on them (flat
        # indices) must widen first
        obs = cls(
            vertex[order].astype(np.int32),
            frame[order].astype(np.int32),
            view[order].astype(np.int32),
            frames.illumination[frame[order]].astype(np.int32),
            None if fixed_rgb is None else np.asarray(fixed_rgb, dtype=float)[order],
        )
        obs._index(n_vertices)
        return obs

    def _index(self, n_vertices: int) -> None:
        v, c = self.vertex, self.view
        new_vertex = np.r_[True, v[1:] != v[:-1]] if v.size else np.zeros(0, bool)
        new_pair = new_vertex | (np.r_[True, c[1:] != c[:-1]] if v.size else new_vertex)
        self.pair_start = np.flatnonzero(new_pair)
        self.per_vertex = np.bincount(v, minlength=n_vertices)

    @property
    def count(self) -> int:
        return int(self.vertex.size)


@dataclass
class Weights:
    """γ = (spectral, photometric, geometric) weights, per-edge photometric weights w_ij
    (edges (E, 2), i < j), the per-vertex geometric scale l_i (metres), the unit of the
    rendering term: image values are multiplied by ``rendering_scale`` before differencing
    (255 = 8-bit units, the units the paper's γ were tuned in), and a factor per observation
    on its rendering residual (M,) in the observations' order (highlights down-weighted,
    :mod:`reconstruct.optimise.highlights`; None: all 1)."""

    gamma: tuple[float, float, float]
    edges: np.ndarray
    edge_weight: np.ndarray
    scale: np.ndarray
    rendering_scale: float = 1.0
    observation: np.ndarray | None = None
    spectral: SpectralRegulariser | None = None  # what γ1 weighs; None: the paper's smoothness
    # a highlight per observation (M, 3) taken off what it observed (reconstruct.optimise.gloss)
    observed_offset: np.ndarray | None = None


@dataclass
class Problem:
    """Everything a joint solve needs besides θ."""

    faces: np.ndarray
    n_vertices: int
    basis: np.ndarray  # B (N_λ, N_b)
    rig: Rig
    frames: Frames
    obs: Observations
    weights: Weights
    light_mode: LightMode = "offset"

    def __post_init__(self) -> None:
        if self.light_mode not in ("offset", "free"):
            raise RigError(
                f"light mode {self.light_mode!r} is unknown",
                "use `offset` (light on the camera plate) or `free` (one position per view)",
            )
        if self.obs.fixed_rgb is None and self.frames.images is None:
            raise RigError(
                "observations have neither fixed values nor images to sample",
                "pass decoded frames (Frames.images) or fixed observed RGB values",
            )

    @property
    def n_basis(self) -> int:
        return int(self.basis.shape[1])

    @property
    def n_light(self) -> int:
        return 3 if self.light_mode == "offset" else 3 * self.rig.n_views

    @property
    def size(self) -> int:
        return 3 * self.n_vertices + self.n_basis * self.n_vertices + self.n_light

    def slices(self) -> tuple[slice, slice, slice]:
        """Where X, A and the light parameters sit in θ."""
        nx = 3 * self.n_vertices
        na = self.n_basis * self.n_vertices
        return slice(0, nx), slice(nx, nx + na), slice(nx + na, nx + na + self.n_light)

    def pack(self, X: np.ndarray, A: np.ndarray, light: np.ndarray) -> np.ndarray:
        return np.concatenate([np.ravel(X), np.ravel(A), np.ravel(light)]).astype(float, copy=False)

    def unpack(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        sx, sa, sl = self.slices()
        return (
            theta[sx].reshape(-1, 3),
            theta[sa].reshape(-1, self.n_basis),
            theta[sl].reshape(-1, 3),
        )

    def light_positions(self, light: np.ndarray) -> np.ndarray:
        """World light position per view (N_views, 3): eq. 17 ``p_c = R_c^T (v − t_c)`` for the
        shared offset, or the free positions themselves."""
        light = np.asarray(light, dtype=float).reshape(-1, 3)
        if self.light_mode == "free":
            return light
        return np.stack([pose.light_position(light[0]) for pose in self.rig.poses])

    def light_maps(self) -> np.ndarray:
        """``∂p_c/∂(light params of c)``: (N_views, 3, 3) — R_c^T (offset) or I (free)."""
        if self.light_mode == "free":
            return np.broadcast_to(np.eye(3), (self.rig.n_views, 3, 3)).copy()
        return np.stack([pose.R.T for pose in self.rig.poses])

    def mask(self, free_positions: bool, free_reflectance: bool, free_light: bool) -> np.ndarray:
        """Boolean mask over θ of the parameters a stage optimises."""
        sx, sa, sl = self.slices()
        m = np.zeros(self.size, dtype=bool)
        m[sx], m[sa], m[sl] = free_positions, free_reflectance, free_light
        return m
