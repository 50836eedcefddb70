"""The working resolution of each stage: which level of the image pyramid (level L is the
frame halved L times) decode stores, PatchMatch matches at and the optimiser samples.

A ``detail`` preset caps the decoded frames' long side, as COLMAP's ``max_image_size`` caps
its dense stage (2000 by default): ``draft`` 1000 px, ``standard`` 2000, ``fine`` 4000. Every
later stage works on those frames at the levels the target mesh edge asks for, measured in
their pixels at the object (the footprint: the cameras' distance to the point they look at
over their focal length):

- the optimiser samples the level at which the target edge spans more than 1 and at most 2
  pixels (finer pixels add memory, not detail the mesh can hold);
- PatchMatch matches one level below the optimiser (a pixel per one to two target edges: its
  points only seed the mesh that subdivision resamples to the target edge);
- subdivision aims at the target edge.

The target edge is ``subdivide.target_px`` (2) pixels of the decoded frames unless
``edge_mm`` gives it in millimetres (then the footprint turns it into pixels, and
subdivision aims at it in metres). Frames no larger than the preset (800×600 at every
preset) stay at level 0 and the stages work as they always did: PatchMatch at half size, the
optimiser at full size, edges of 2 px.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np

from core.config import bounded
from core.errors import RigError
from reconstruct.model.camera import Intrinsics, Pose

Detail = Literal["draft", "standard", "fine"]
# the decoded frames' largest long side (px) per preset
MAX_SIDE: dict[str, int] = {"draft": 1000, "standard": 2000, "fine": 4000}


@dataclass(frozen=True)
class ResolutionConfig:
    """The ``resolution`` section: ``detail`` preset (the decoded frames' largest long side),
    ``edge_mm``: the wanted mesh edge in millimetres (metric poses only; unset: 2 px of the
    decoded frames)."""

    detail: Detail = "standard"
    edge_mm: float | None = bounded(None, above=0.0, max=1e4)


@dataclass(frozen=True)
class StageLevels:
    """The preset, the pyramid level of each stage counted from the RAW frame (level 0), the
    target edge in pixels of the decoded frames, and the footprint (mm per decoded pixel)."""

    detail: str
    decode: int
    patchmatch: int
    optimise: int
    edge_px: float
    mm_per_px: float | None  # at the decoded level; None without metric poses

    @property
    def patchmatch_scale(self) -> float:
        """PatchMatch's image scale relative to the decoded frames."""
        return 0.5 ** (self.patchmatch - self.decode)

    @property
    def optimise_step(self) -> int:
        """Levels between the decoded frames and the optimiser's."""
        return self.optimise - self.decode

    @property
    def edge_mm(self) -> float | None:
        return None if self.mm_per_px is None else self.edge_px * self.mm_per_px

    def to_dict(self) -> dict[str, Any]:
        return asdict(self) | {"edge_mm": self.edge_mm}


def frame_level(width: int, height: int, max_side: int) -> int:
    """The finest level whose long side is at most ``max_side`` (0: keep the full size)."""
    if max_side <= 0:
        return 0
    return max(0, math.ceil(math.log2(max(width, height) / max_side)))


def level_size(width: int, height: int, steps: int) -> tuple[int, int]:
    """(width, height) of an image halved ``steps`` times (rounded as cv2.resize and
    ``patchmatch.scaled`` round)."""
    f = 0.5**steps
    return max(1, round(width * f)), max(1, round(height * f))


def optimise_steps(edge_px: float) -> int:
    """Halvings after which ``edge_px`` spans more than 1 and at most 2 pixels."""
    return max(0, math.ceil(math.log2(edge_px)) - 1)


def patchmatch_steps(edge_px: float) -> int:
    """Halvings after which one pixel spans one to two edges of ``edge_px`` pixels."""
    return optimise_steps(edge_px) + 1


def mm_per_px(intrinsics: Mapping[int, Intrinsics], poses: Mapping[int, Pose]) -> float:
    """Millimetres one pixel spans at the object: median over the views of the distance to the
    point closest to every optical axis (what the cameras look at), over the focal length.
    Metres in, so metric poses give millimetres."""
    views = [v for v in sorted(poses) if v in intrinsics]
    if len(views) < 2:
        raise RigError(
            f"only {len(views)} posed view(s): the object's distance cannot be told",
            "pose at least two views (more of the board or object in view)",
        )
    centres = np.array([poses[v].center for v in views])
    axes = np.array([poses[v].R[2] for v in views])  # optical axes in the world frame
    # least squares: sum over views of (I - a aᵀ)(p - c) = 0
    proj = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]
    target = np.linalg.lstsq(proj.sum(0), np.einsum("vij,vj->i", proj, centres), rcond=None)[0]
    depth = np.einsum("vi,vi->v", target - centres, axes)
    focal = np.array([float(np.sqrt(intrinsics[v].K[0, 0] * intrinsics[v].K[1, 1]))
                      for v in views])
    return float(np.median(np.abs(depth) / focal)) * 1e3


def choose(
    conf: ResolutionConfig,
    decode_level: int,
    target_px: float,
    footprint: float | None,
    patchmatch_scale: float | None = None,
) -> StageLevels:
    """Each stage's level from the decoded frames' level, the default edge (``target_px``
    decoded pixels), the footprint (mm per decoded pixel; None: poses not metric) and
    PatchMatch's scale when the config names one."""
    edge_px = target_px
    if conf.edge_mm is not None:
        if footprint is None:
            raise RigError(
                "resolution.edge_mm needs metric poses (the board, known poses or "
                "known_distances), but these poses have no scale",
                "leave edge_mm out and choose --detail, or give the session a metric scale",
            )
        edge_px = conf.edge_mm / footprint
    return StageLevels(
        detail=conf.detail,
        decode=decode_level,
        patchmatch=decode_level + (
            patchmatch_steps(edge_px) if patchmatch_scale is None
            else max(0, round(-math.log2(patchmatch_scale)))
        ),
        optimise=decode_level + optimise_steps(edge_px),
        edge_px=edge_px,
        mm_per_px=footprint,
    )
