"""Detection on rendered views: corners where the truth projects them, visibility report."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import cv2
import numpy as np
import pytest

from core.errors import RigError
from reconstruct.model.camera import Pose, project
from reconstruct.poses.board import board_visibility_report, detect_board, linear_to_u8


@pytest.fixture(scope="module")
def view(scene: Any) -> Pose:
    return Pose.look_at(np.array([0.25, -0.3, 0.35]), np.array([0.01, 0.0, 0.0]))


def test_corners_subpixel_under_blur_noise_and_occlusion(
    scene: Any, view: Pose, render_view: Callable[..., np.ndarray]
) -> None:
    rng = np.random.default_rng(3)
    image = render_view(scene, view, rng, occluder_m=0.04, blur_sigma=1.0, noise_dn=3.0)
    det = detect_board(image, scene.spec)
    # The object hides the middle of the board; most of the rest is found.
    assert 20 <= det.n_corners < scene.spec.n_corners
    truth = project(scene.intrinsics, view, det.object_points)
    error = np.linalg.norm(det.corners - truth, axis=1)
    assert np.sqrt(np.mean(error**2)) < 0.1
    assert error.max() < 0.3
    # Hidden corners are not reported: nothing within the object's footprint.
    assert np.linalg.norm(det.object_points[:, :2], axis=1).min() > 0.04
    assert np.all(np.isin(det.ids, np.arange(scene.spec.n_corners)))


def test_rgb_and_grey_inputs_agree(
    scene: Any, view: Pose, render_view: Callable[..., np.ndarray]
) -> None:
    image = render_view(scene, view, np.random.default_rng(4), occluder_m=0.0)
    grey = detect_board(image, scene.spec)
    rgb = detect_board(np.repeat(image[:, :, None], 3, axis=2), scene.spec)
    assert grey.n_corners == scene.spec.n_corners
    assert np.array_equal(grey.ids, rgb.ids)
    assert np.allclose(grey.corners, rgb.corners, atol=1e-3)


def test_visibility_report(scene: Any, view: Pose, render_view: Callable[..., np.ndarray]) -> None:
    rng = np.random.default_rng(5)
    bright = render_view(scene, view, rng, occluder_m=0.0)
    n, contrast = board_visibility_report(bright, scene.spec)
    assert n == scene.spec.n_corners
    # Paper 0.85, ink 0.05, lit 0.75-1.0 across the view: about 0.6-0.8 of full scale.
    assert 0.55 < contrast < 0.85
    dim = render_view(scene, view, rng, occluder_m=0.0, gain=0.25)
    n_dim, contrast_dim = board_visibility_report(dim, scene.spec)
    assert n_dim > 0
    assert contrast_dim == pytest.approx(contrast / 4, rel=0.15)
    # Board out of view: nothing found, zero contrast.
    away = Pose.look_at(np.array([0.0, 0.0, 0.5]), np.array([0.0, 2.0, 0.4]))
    assert board_visibility_report(render_view(scene, away, rng), scene.spec) == (0, 0.0)


def test_linear_frames_need_conversion(
    scene: Any, view: Pose, render_view: Callable[..., np.ndarray]
) -> None:
    image = render_view(scene, view, np.random.default_rng(6), occluder_m=0.0)
    linear = (image.astype(float) / 255.0) ** 2.2 * 0.01  # a dim linear RAW-like frame
    with pytest.raises(RigError, match="8-bit"):
        detect_board(linear, scene.spec)
    assert detect_board(linear_to_u8(linear), scene.spec).n_corners == scene.spec.n_corners


def test_no_board_is_found_in_real_photographs(shared_data: Any, scene: Any) -> None:
    """Real, richly textured photographs without a board: no false corners."""
    images = sorted((shared_data / "multiview" / "sceaux_castle" / "images").glob("*.JPG"))[:3]
    assert images
    for path in images:
        photo = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        assert photo is not None, path
        photo = cv2.resize(photo, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
        assert board_visibility_report(photo, scene.spec) == (0, 0.0), path.name
