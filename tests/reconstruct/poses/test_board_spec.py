"""Board geometry, profile snippet and printed texture."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from core.errors import RigError
from reconstruct.poses.board import BoardSpec, board_texture, detect_board


def test_fit_paper_a4_fits_inside_margins() -> None:
    spec = BoardSpec.fit_paper("A4", squares=(10, 7))
    w, h = spec.size_m
    pw, ph = spec.paper_size_m() or (0, 0)
    assert (pw, ph) == pytest.approx((0.297, 0.210))  # landscape for a wide board
    assert spec.square_length_m == pytest.approx(0.026)  # whole millimetres
    assert w <= pw - 0.024 and h <= ph - 0.024
    assert spec.marker_length_m == pytest.approx(0.75 * 0.026)


def test_fit_paper_rejects_a_square_that_does_not_fit() -> None:
    with pytest.raises(RigError, match="do not fit on A4"):
        BoardSpec.fit_paper("A4", squares=(10, 7), square_length_m=0.04)


def test_snippet_round_trip_and_measured_scale(tmp_path: Path) -> None:
    spec = BoardSpec.fit_paper("A3", squares=(9, 6))
    path = tmp_path / "board.yaml"
    path.write_text(spec.to_yaml())
    assert BoardSpec.from_yaml(path) == spec
    measured = spec.with_measured_square(spec.square_length_m * 0.98)
    path.write_text(measured.to_yaml())
    back = BoardSpec.from_yaml(path)
    assert back.scale == pytest.approx(0.98)
    assert back.marker_m == pytest.approx(spec.marker_length_m * 0.98)
    assert back.corner_points()[1, 0] - back.corner_points()[0, 0] == pytest.approx(
        spec.square_length_m * 0.98
    )
    # A whole profile with a board: entry works too.
    profile = {"camera": {"backend": "sim"}, **yaml.safe_load(path.read_text())}
    assert BoardSpec.from_dict(profile) == back


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"squares": [7, 5], "square_length_m": 0.03}, "'board.marker_length_m' is missing"),
        ({"squares": [7, 5], "square_length_m": 0.03, "marker_length_m": 0.04}, "smaller"),
        (
            {
                "squares": [7, 5],
                "square_length_m": 0.03,
                "marker_length_m": 0.02,
                "dictionary": "DICT_9X9",
            },
            "dictionary 'DICT_9X9' is unknown",
        ),
        (
            {
                "squares": [20, 20],
                "square_length_m": 0.01,
                "marker_length_m": 0.007,
                "dictionary": "DICT_4X4_50",
            },
            "needs 200 markers",
        ),
        ({"squares": "7x5", "square_length_m": 0.03, "marker_length_m": 0.02},
         "'board.squares' is '7x5'"),
    ],
)
def test_bad_snippets_name_the_key(entry: dict, message: str) -> None:
    with pytest.raises(RigError, match=message) as exc:
        BoardSpec.from_dict({"board": entry}, source="rig.yaml")
    assert "rig.yaml" in str(exc.value) or "board" in str(exc.value)


def test_world_frame_is_centred_and_z_up() -> None:
    spec = BoardSpec.fit_paper("A4")
    corners = spec.corner_points()
    assert np.allclose(corners.mean(axis=0), 0.0, atol=1e-12)
    assert np.allclose(corners[:, 2], 0.0)
    # Corner 0 is the top-left inner corner as printed: left (x < 0) and top (y > 0).
    assert corners[0, 0] < 0 < corners[0, 1]
    # OpenCV's frame (y down, z into the paper) maps by a proper rotation: handedness kept.
    axes = spec.to_world(np.eye(3)) - spec.to_world(np.zeros((1, 3)))
    assert np.allclose(axes, np.diag([1.0, -1.0, -1.0]))
    assert np.linalg.det(axes) == pytest.approx(1.0)


@pytest.mark.parametrize("legacy", [False, True])
@pytest.mark.parametrize("squares", [(10, 7), (6, 6), (5, 4)])
def test_geometry_matches_opencv_board(squares: tuple[int, int], legacy: bool) -> None:
    spec = BoardSpec(squares, 0.03, 0.022, legacy_pattern=legacy)
    board = spec.cv_board()
    cv_corners = spec.to_world(np.asarray(board.getChessboardCorners()))
    assert np.abs(spec.corner_points() - cv_corners).max() < 1e-7
    ids = np.asarray(board.getIds()).ravel()
    cv_markers = spec.to_world(np.asarray(board.getObjPoints()).reshape(-1, 3)).reshape(-1, 4, 3)
    assert np.abs(spec.marker_points()[ids] - cv_markers).max() < 1e-7


def test_texture_ink_area_and_margin() -> None:
    spec = BoardSpec.fit_paper("A4")
    px_per_m = 2000.0
    image, (x0, y0, x1, y1) = board_texture(spec, px_per_m)
    assert image.shape == (round(0.210 * px_per_m), round(0.297 * px_per_m))
    assert (x1 - x0) * px_per_m == pytest.approx(image.shape[1])
    assert (y1 - y0) * px_per_m == pytest.approx(image.shape[0])
    rects = spec.black_rectangles()
    ink_area = np.sum((rects[:, 2] - rects[:, 0]) * (rects[:, 3] - rects[:, 1]))
    # Exact box-filtered coverage: the texture's ink equals the rectangles' area.
    assert np.sum(1.0 - image) / px_per_m**2 == pytest.approx(ink_area, rel=1e-9)
    assert image.min() >= 0.0 and image.max() <= 1.0
    # White paper margin all round; the corner square of the board is ink.
    assert np.all(image[:10] == 1.0) and np.all(image[:, -10:] == 1.0)
    bw, bh = spec.size_m
    col = int((-bw / 2 + spec.square_m / 2 - x0) * px_per_m)
    row = int((y1 - (bh / 2 - spec.square_m / 2)) * px_per_m)
    assert image[row, col] == 0.0


@pytest.mark.parametrize(
    "spec",
    [BoardSpec.fit_paper("A4"), BoardSpec((6, 6), 0.03, 0.022, legacy_pattern=True)],
    ids=["a4", "legacy-6x6"],
)
def test_texture_detects_at_the_printed_positions(spec: BoardSpec) -> None:
    """The texture, read as a fronto-parallel image, is detected with every corner at the
    position its world coordinates give: layout, ids and the y-up frame all agree."""
    px_per_m = 4000.0
    image, (x0, _, _, y1) = board_texture(spec, px_per_m)
    det = detect_board(np.round(255 * image).astype(np.uint8), spec)
    assert det.n_corners == spec.n_corners
    expected = np.stack(
        [(det.object_points[:, 0] - x0) * px_per_m, (y1 - det.object_points[:, 1]) * px_per_m],
        axis=1,
    )
    assert np.abs(det.corners - expected).max() < 0.02


def test_texture_without_paper_has_one_square_margin() -> None:
    spec = BoardSpec((5, 4), 0.02, 0.015)
    image, (x0, y0, x1, y1) = board_texture(spec, 1000.0)
    assert (x1 - x0) == pytest.approx(5 * 0.02 + 2 * 0.02)
    assert (y1 - y0) == pytest.approx(4 * 0.02 + 2 * 0.02)
    with pytest.raises(RigError, match="px/m"):
        board_texture(spec, 0.0)
