"""The capture's quick board look: the grey image built from the mosaic matches LibRaw's, and
the binned search falls back to full size before it reports a view as missing the board."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import rawpy

from drivers.sim.dng import write_dng
from reconstruct.poses.board import BoardSpec, board_visibility_report
from rig.capture.board_check import BoardLook, board_binnings, board_image, look_for_board
from rig.capture.frames import RawData, read_raw

SPEC = BoardSpec.fit_paper("A4")
BLACK, WHITE = 512, 16383
NEUTRAL = np.array([0.45, 1.0, 0.7])  # camera RGB of a grey under the shot's light


def board_mosaic(board_px: int, seed: int = 0) -> np.ndarray:
    """A 640x480 RGGB mosaic of the board, ``board_px`` wide on a grey table, lit unevenly."""
    h, w = 480, 640
    sheet = SPEC.cv_board().generateImage(
        (board_px, round(board_px * SPEC.size_m[1] / SPEC.size_m[0])), marginSize=8
    )
    scene = np.full((h, w), 90, np.uint8)
    y0, x0 = (h - sheet.shape[0]) // 2, (w - sheet.shape[1]) // 2
    scene[y0 : y0 + sheet.shape[0], x0 : x0 + sheet.shape[1]] = sheet
    shading = np.linspace(0.35, 0.6, w)[None, :]  # a light off to one side
    linear = (np.asarray(cv2.GaussianBlur(scene, (0, 0), 0.8)) / 255.0) ** 2.2 * shading
    camera = linear * np.tile(
        np.array([[NEUTRAL[0], NEUTRAL[1]], [NEUTRAL[1], NEUTRAL[2]]]), (h // 2, w // 2)
    )
    rng = np.random.default_rng(seed)
    dn = BLACK + camera * (WHITE - BLACK) + rng.normal(0, 4, camera.shape)
    return np.clip(np.round(dn), 0, WHITE).astype(np.uint16)


def test_grey_look_from_the_mosaic_matches_libraw(tmp_path: Path) -> None:
    path = tmp_path / "frame.dng"
    write_dng(
        path,
        board_mosaic(560),
        black_level=BLACK,
        white_level=WHITE,
        exposure_s=0.5,
        iso=100,
        make="spectral-rig",
        model="Test",
        serial="1",
        color_matrix=np.eye(3),
        as_shot_neutral=NEUTRAL,
    )
    ours = board_image(read_raw(path), 1)
    with rawpy.imread(str(path)) as raw:
        libraw = raw.postprocess(
            demosaic_algorithm=rawpy.DemosaicAlgorithm.LINEAR,
            use_camera_wb=True,
            no_auto_bright=True,
            output_bps=8,
        )
    grey = cv2.cvtColor(libraw, cv2.COLOR_RGB2GRAY).astype(float)
    assert ours.shape == grey.shape and ours.dtype == np.uint8
    assert np.median(np.abs(ours - grey)) <= 2.0
    n, contrast = board_visibility_report(ours, SPEC)
    n_libraw, contrast_libraw = board_visibility_report(libraw, SPEC)
    assert n == n_libraw == SPEC.n_corners
    assert contrast == pytest.approx(contrast_libraw, abs=0.03)


def raw_of(mosaic: np.ndarray) -> RawData:
    gain = 1.0 / np.array([[NEUTRAL[0], NEUTRAL[1]], [NEUTRAL[1], NEUTRAL[2]]]) / (WHITE - BLACK)
    return RawData(mosaic, BLACK, WHITE, np.full((2, 2), float(BLACK)), gain)


@pytest.mark.parametrize("board_px", [600, 400, 250])
def test_quick_look_never_reports_fewer_corners_than_needed(board_px: int) -> None:
    """Whenever the full-size look has enough corners for a pose, so has the reported one."""
    raw = raw_of(board_mosaic(board_px))
    full = board_visibility_report(board_image(raw, 1), SPEC)[0]
    look = look_for_board(raw, SPEC, 6)
    assert full >= 6
    assert look.corners >= 6
    if board_px == 600:  # large in the frame: the half-size look is enough
        assert look.binning == 2
    if board_px == 250:  # too small for the half-size look: found at full size
        assert look.binning == 1 and look.corners == full


def test_no_board_falls_back_and_finds_nothing() -> None:
    rng = np.random.default_rng(2)
    mosaic = rng.integers(2000, 9000, (480, 640)).astype(np.uint16)
    assert look_for_board(raw_of(mosaic), SPEC, 6) == BoardLook(0, 0.0, 1)


def test_binnings_follow_the_sensor_size() -> None:
    small = raw_of(np.zeros((480, 640), np.uint16))
    large = raw_of(np.zeros((3744, 5616), np.uint16))
    assert board_binnings(small) == (2, 1)
    assert board_binnings(large) == (4, 2)
    assert board_image(large, 4).shape == (936, 1404)
    assert board_binnings(RawData(np.zeros((100, 100, 3)), 0.0, 1.0)) == (2, 1)
