"""Bilinear sampling at projections and the projection Jacobian."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.optimise.kernels.sampling import project_points
from reconstruct.optimise.sampling import (
    bilinear,
    bilinear_taps,
    sample_pairs,
    sample_taps,
    taps_valid,
    view_cameras,
)


def test_pixel_centres_and_linear_images_are_exact() -> None:
    h, w = 7, 9
    rows, cols = np.mgrid[0:h, 0:w]
    img = np.stack([2.0 * cols + 3.0 * rows, cols - rows, np.ones_like(cols)], axis=-1)[None]
    # The centre of element [row, col] is at pixel coordinates (col + 0.5, row + 0.5).
    value, _ = bilinear(img, np.array([0]), np.array([[3.5, 2.5]]))
    assert np.allclose(value, img[0, 2, 3])
    uv = np.array([[1.2, 1.7], [4.9, 3.1], [7.3, 5.8]])
    value, grad = bilinear(img, np.zeros(3, dtype=int), uv)
    c, r = uv[:, 0] - 0.5, uv[:, 1] - 0.5
    assert np.allclose(value[:, 0], 2 * c + 3 * r)
    assert np.allclose(grad[:, 0], [2.0, 3.0])
    assert np.allclose(grad[:, 1], [1.0, -1.0])
    assert np.allclose(grad[:, 2], 0.0)


def test_gradient_matches_finite_differences_inside_a_cell() -> None:
    rng = np.random.default_rng(1)
    img = rng.uniform(size=(2, 6, 8, 3))
    uv = np.array([[2.3, 3.2], [5.6, 1.9]])
    frame = np.array([1, 0])
    _, grad = bilinear(img, frame, uv)
    h = 1e-6
    for k in range(2):
        d = np.zeros(2)
        d[k] = h
        fd = (bilinear(img, frame, uv + d)[0] - bilinear(img, frame, uv - d)[0]) / (2 * h)
        assert np.allclose(grad[:, :, k], fd, atol=1e-7)


def test_taps_valid_excludes_saturated_neighbourhoods_and_borders() -> None:
    valid = np.ones((1, 6, 6), dtype=bool)
    valid[0, 3, 3] = False
    uv = np.array([[3.9, 3.9], [1.6, 1.6], [0.2, 3.0], [np.nan, 2.0]])
    ok = taps_valid(valid, np.zeros(4, dtype=int), uv, margin=1.0)
    assert ok.tolist() == [False, True, False, False]


def test_projection_jacobian_with_distortion() -> None:
    intr = Intrinsics("OPENCV", 640, 480, (700.0, 690.0, 320.0, 240.0, -0.2, 0.05, 1e-3, -2e-3))
    pose = Pose.look_at(np.array([0.4, -0.3, 0.2]), np.zeros(3))
    rng = np.random.default_rng(2)
    x = 0.05 * rng.normal(size=(5, 3))
    idx = np.arange(len(x))
    uv, duv = project_points(x, idx, np.zeros_like(idx), *view_cameras([intr], [pose]), True)
    assert np.allclose(uv, intr.project_camera(pose.to_camera(x)))
    h = 1e-7
    for k in range(3):
        d = np.zeros(3)
        d[k] = h
        fd = intr.project_camera(pose.to_camera(x + d)) - intr.project_camera(pose.to_camera(x - d))
        assert np.allclose(duv[:, :, k], fd / (2 * h), rtol=1e-5, atol=1e-3)


def test_shared_taps_sample_every_frame_of_a_view() -> None:
    """One projection's taps read any frame: the same values and gradients as sampling each
    frame on its own."""
    rng = np.random.default_rng(4)
    img = rng.uniform(size=(3, 6, 8, 3)).astype(np.float32)
    uv = np.array([[2.3, 3.2], [5.6, 1.9], [0.1, 7.0]])
    taps = bilinear_taps(img.shape[1:3], uv)
    for f in range(3):
        frame = np.full(len(uv), f)
        value, grad = sample_taps(img, frame, taps, gradient=True)
        assert grad is not None
        ref_value, ref_grad = bilinear(img, frame, uv)
        assert np.allclose(value, ref_value) and np.allclose(grad, ref_grad)
        coords = [uv[:, 1] - 0.5, uv[:, 0] - 0.5]  # (row, col) of the array elements
        ndi = np.stack(
            [map_coordinates(img[f, :, :, c], coords, order=1, mode="nearest") for c in range(3)],
            axis=1,
        )
        assert np.allclose(value, ndi, atol=1e-5)
        only, none = sample_taps(img, frame, taps, gradient=False)
        assert np.array_equal(only, value) and none is None


def test_points_behind_the_camera_are_clamped_not_an_error() -> None:
    img = np.arange(2 * 5 * 6 * 3, dtype=float).reshape(2, 5, 6, 3)
    uv = np.array([[np.nan, np.nan], [np.inf, -np.inf], [2.5, 2.5]])
    value, grad = bilinear(img, np.array([1, 1, 1]), uv)
    assert np.all(np.isfinite(value)) and np.all(np.isfinite(grad))
    assert np.allclose(value[0], img[1, 0, 0]) and np.allclose(value[1], img[1, 0, 5])


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.float64])
def test_compiled_sampler_matches_the_numpy_one(dtype: type) -> None:
    """The cost samples through ``kernels.sample_bilinear`` (taps per pair, frames per
    observation); it must give the same values and gradients as :func:`sample_taps`, for the
    float16 frames of the pipeline (read by bit pattern) as for float32/64."""
    from reconstruct.optimise.kernels.sampling import sample_bilinear

    rng = np.random.default_rng(3)
    images = rng.uniform(size=(4, 9, 11, 3)).astype(dtype)
    uv = rng.uniform([-1.0, -1.0], [12.0, 10.0], size=(5, 2))  # some off the image: clamped
    index, fc, fr = bilinear_taps((9, 11), uv)
    obs_pair = np.array([0, 0, 1, 2, 2, 3, 4, 4])
    frame = rng.integers(0, 4, obs_pair.size)
    taps = (index[obs_pair], fc[obs_pair], fr[obs_pair])
    want, want_grad = sample_taps(images, frame, taps, gradient=True)
    frac = np.concatenate([fc, fr], axis=1)
    value, grad = sample_bilinear(images, frame, obs_pair, index, frac, True)
    assert np.allclose(value, want, rtol=1e-6, atol=1e-6)
    assert np.allclose(grad, want_grad, rtol=1e-6, atol=1e-6)
    value, grad = sample_bilinear(images, frame, obs_pair, index, frac, False)
    assert np.allclose(value, want, rtol=1e-6, atol=1e-6) and grad.size == 0
    # the same through sample_pairs (taps from the pairs' pixel coords)
    value, grad = sample_pairs(images, frame, obs_pair, uv, True)
    assert np.allclose(value, want, rtol=1e-6, atol=1e-6)
    assert np.allclose(grad, want_grad, rtol=1e-6, atol=1e-6)
