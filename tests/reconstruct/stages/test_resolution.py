"""The working resolution per stage: the decoded frames' level from the preset, PatchMatch's
and the optimiser's levels from the target edge and the footprint (mm per pixel at the object),
and today's behaviour kept where the frames are small."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import RigError
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.stages.resolution import (
    MAX_SIDE,
    ResolutionConfig,
    choose,
    frame_level,
    level_size,
    mm_per_px,
    optimise_steps,
    patchmatch_steps,
)


def look_at(centre: np.ndarray, target: np.ndarray) -> Pose:
    z = (target - centre) / np.linalg.norm(target - centre)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return Pose(R, -R @ centre)


def ring(distance: float, views: int = 8) -> dict[int, Pose]:
    target = np.array([0.01, -0.02, 0.05])
    angles = np.linspace(0, 2 * np.pi, views, endpoint=False)
    return {
        v: look_at(target + distance * np.array([np.cos(a), np.sin(a), 0.4]) / np.hypot(1, 0.4),
                   target)
        for v, a in enumerate(angles)
    }


@pytest.mark.parametrize(
    ("size", "detail", "level"),
    [
        ((800, 600), "draft", 0), ((800, 600), "standard", 0), ((800, 600), "fine", 0),
        ((5616, 3744), "draft", 3), ((5616, 3744), "standard", 2), ((5616, 3744), "fine", 1),
        ((8256, 5504), "standard", 3), ((2000, 1333), "standard", 0), ((2001, 1334), "standard", 1),
    ],
)
def test_decoded_level_is_the_finest_within_the_preset(
    size: tuple[int, int], detail: str, level: int
) -> None:
    assert frame_level(*size, MAX_SIDE[detail]) == level
    assert max(level_size(*size, level)) <= MAX_SIDE[detail]
    assert level == 0 or max(level_size(*size, level - 1)) > MAX_SIDE[detail]


def test_full_size_when_no_cap() -> None:
    assert frame_level(5616, 3744, 0) == 0
    assert level_size(5616, 3744, 2) == (1404, 936)
    assert level_size(5617, 3745, 1) == (2808, 1872)  # rounded as cv2.resize rounds


@pytest.mark.parametrize(
    ("edge_px", "optimise", "patchmatch"),
    [(1.25, 0, 1), (2.0, 0, 1), (2.01, 1, 2), (3.0, 1, 2), (4.0, 1, 2), (8.0, 2, 3),
     (0.5, 0, 1)],
)
def test_stage_steps_from_the_target_edge(edge_px: float, optimise: int, patchmatch: int) -> None:
    assert optimise_steps(edge_px) == optimise
    assert patchmatch_steps(edge_px) == patchmatch
    spacing = edge_px / 2**optimise  # the edge in the optimiser's pixels
    assert spacing <= 2.0 and (spacing > 1.0 or optimise == 0)
    assert patchmatch == optimise + 1  # a PatchMatch pixel per one to two edges


@pytest.mark.parametrize("target_px", [1.25, 2.0])  # bench.real_size's and the default
def test_presets_keep_todays_stages_at_800x600(target_px: float) -> None:
    """Level 0 frames, PatchMatch at half size, the optimiser at full size."""
    for detail in MAX_SIDE:
        level = frame_level(800, 600, MAX_SIDE[detail])
        levels = choose(ResolutionConfig(detail), level, target_px, 0.5)  # type: ignore[arg-type]
        assert (levels.decode, levels.patchmatch, levels.optimise) == (0, 1, 0)
        assert levels.patchmatch_scale == 0.5 and levels.optimise_step == 0
        assert levels.edge_mm == pytest.approx(0.5 * target_px)


def test_a_21mp_frame_works_two_levels_down_at_standard() -> None:
    level = frame_level(5616, 3744, MAX_SIDE["standard"])
    levels = choose(ResolutionConfig(), level, 2.0, None)
    assert (levels.decode, levels.patchmatch, levels.optimise) == (2, 3, 2)
    assert levels.edge_mm is None  # relative poses: no millimetres


def test_footprint_is_distance_over_focal() -> None:
    intr = {v: Intrinsics("PINHOLE", 1404, 936, (2000.0, 2000.0, 702.0, 468.0)) for v in range(8)}
    assert mm_per_px(intr, ring(0.5)) == pytest.approx(0.25, rel=1e-9)
    assert mm_per_px(intr, ring(1.0)) == pytest.approx(0.5, rel=1e-9)
    with pytest.raises(RigError, match="two views"):
        mm_per_px(intr, {0: ring(0.5)[0]})


def test_an_edge_in_mm_chooses_the_levels_from_the_footprint() -> None:
    footprint = 0.25  # mm per decoded pixel
    levels = choose(ResolutionConfig("draft", edge_mm=1.0), 1, 2.0, footprint)
    assert levels.edge_px == pytest.approx(4.0)
    assert (levels.decode, levels.patchmatch, levels.optimise) == (1, 3, 2)
    assert levels.patchmatch_scale == 0.25 and levels.optimise_step == 1
    # finer than the decoded frames resolve: the optimiser at their level
    fine = choose(ResolutionConfig(edge_mm=0.1), 1, 2.0, footprint)
    assert (fine.patchmatch, fine.optimise) == (2, 1)
    # a PatchMatch scale named in the config is reported as its level
    assert choose(ResolutionConfig(), 0, 2.0, footprint, 0.25).patchmatch == 2


def test_an_edge_in_mm_needs_metric_poses() -> None:
    with pytest.raises(RigError, match="metric poses"):
        choose(ResolutionConfig(edge_mm=1.0), 0, 2.0, None)
