"""A printed ChArUco board under the object: metric, gravity-aligned poses without texture.

Smooth, uniformly painted objects give SfM too few features, and SfM never gives metric
scale, which the inverse-square light model needs. The board gives both. World frame: the
board's (origin at its centre, z up, metres).
"""

from reconstruct.poses.board.detect import (
    Detection,
    board_visibility_report,
    detect_board,
    linear_to_u8,
)
from reconstruct.poses.board.merge import MergedPoses, Similarity, merge_with_sfm, umeyama
from reconstruct.poses.board.poses import (
    BoardPoseResult,
    adjust,
    board_poses,
    corner_residuals,
    estimate_intrinsics,
    solve_view_pose,
)
from reconstruct.poses.board.printout import write_sheet
from reconstruct.poses.board.spec import PAPER_SIZES_M, BoardSpec
from reconstruct.poses.board.texture import board_texture

__all__ = [
    "PAPER_SIZES_M",
    "BoardPoseResult",
    "BoardSpec",
    "Detection",
    "MergedPoses",
    "Similarity",
    "adjust",
    "board_poses",
    "board_texture",
    "board_visibility_report",
    "corner_residuals",
    "detect_board",
    "estimate_intrinsics",
    "linear_to_u8",
    "merge_with_sfm",
    "solve_view_pose",
    "umeyama",
    "write_sheet",
]
