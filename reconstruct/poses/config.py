"""The poses stage's configuration (the ``poses`` section of a reconstruct config)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from core.config import bounded

MIN_VIEWS = 3


@dataclass(frozen=True)
class PosesConfig:
    """``source``: auto | known | board | sfm (see :mod:`reconstruct.poses.stage`);
    ``use_known``: let ``auto`` read ``SESSION/poses`` when present; ``matcher``: exhaustive,
    sequential or auto (exhaustive up to 60 views); ``max_features``: SIFT features per image;
    ``refine_intrinsics``: let bundle adjustment refine given intrinsics.

    Board: ``board_with_sfm`` also runs SfM and merges it in (``auto``: only when the board
    leaves a view unposed — SfM then adds nothing but minutes); ``board_min_corners`` /
    ``board_max_rms_px``: a view gets a board pose with at least this many corners and at most
    this RMS error; ``board_model``: camera model estimated from the board views when the
    profile gives no intrinsics; ``board_refine_intrinsics``: free given intrinsics in the
    board adjustment (None: only when estimated).

    The defaults suit the rig: a small object turning under a lamp that moves with the camera,
    so few, strongly changing features. Affine-covariant SIFT with domain-size pooling, guided
    matching and a 30-inlier initial pair register the simulated 40-view rings fully where
    COLMAP's photo defaults (upright DoG, 100 inliers) split them into fragments.
    """

    source: Literal["auto", "known", "board", "sfm"] = "auto"
    use_known: bool = True
    matcher: Literal["auto", "exhaustive", "sequential"] = "auto"
    max_features: int = bounded(8192, min=1, max=1_000_000)
    affine_sift: bool = True
    guided_matching: bool = True
    init_min_inliers: int = bounded(30, min=1, max=100_000)
    refine_intrinsics: bool = False
    num_threads: int = bounded(-1, min=-1, max=1024)  # -1: all cores
    board_with_sfm: bool | Literal["auto"] = "auto"
    board_min_corners: int = bounded(6, min=1, max=100_000)
    board_max_rms_px: float = bounded(3.0, above=0.0, max=1000.0)
    board_model: str = "RADIAL"
    board_refine_intrinsics: bool | None = None
