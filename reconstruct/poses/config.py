"""The poses stage's configuration (the ``poses`` section of a reconstruct config)."""

from __future__ import annotations

from dataclasses import dataclass

from core.errors import RigError

MIN_VIEWS = 3
SOURCES = ("auto", "known", "board", "sfm")

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

    source: str = "auto"
    use_known: bool = True
    matcher: str = "auto"
    max_features: int = 8192
    affine_sift: bool = True
    guided_matching: bool = True
    init_min_inliers: int = 30
    refine_intrinsics: bool = False
    num_threads: int = -1
    board_with_sfm: bool | str = "auto"
    board_min_corners: int = 6
    board_max_rms_px: float = 3.0
    board_model: str = "RADIAL"
    board_refine_intrinsics: bool | None = None

    def __post_init__(self) -> None:
        if self.source not in SOURCES:
            raise RigError(
                f"poses.source {self.source!r} is unknown", f"use one of {', '.join(SOURCES)}"
            )
        if self.board_with_sfm not in (True, False, "auto"):
            raise RigError(
                f"poses.board_with_sfm {self.board_with_sfm!r} is unknown",
                "use auto, true or false",
            )
        if self.matcher not in ("auto", "exhaustive", "sequential"):
            raise RigError(
                f"poses.matcher {self.matcher!r} is unknown", "use auto, exhaustive or sequential"
            )
