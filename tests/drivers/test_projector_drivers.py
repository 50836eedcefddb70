"""Gray-code patterns (pure functions), decoded by the reconstruction's decoder, and the
pygame projector on SDL's dummy video driver."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import RigError
from core.graycode import bit_count
from drivers.projectors.patterns import gray_code_image, gray_code_sequence, uniform_image
from reconstruct.initial_mesh.structured_light import decode_gray


@pytest.mark.parametrize(("width", "height"), [(1, 1), (7, 3), (64, 48), (100, 37)])
def test_sequence_has_each_bit_and_its_inverse_for_any_resolution(width: int, height: int) -> None:
    sequence = gray_code_sequence(width, height)
    assert len(sequence) == 2 * (bit_count(width) + bit_count(height))
    for (name, image), (inv_name, inverse) in zip(sequence[::2], sequence[1::2], strict=True):
        assert inv_name == name + "-inv"
        assert image.shape == (height, width) and image.dtype == np.uint8
        assert np.array_equal(image ^ inverse, np.full((height, width), 255, np.uint8))


def test_columns_vary_along_x_only_and_msb_splits_the_screen() -> None:
    image = gray_code_image(8, 4, "col", 0)
    assert np.array_equal(image[0], [0, 0, 0, 0, 255, 255, 255, 255])
    assert np.all(image == image[0])
    rows = gray_code_image(8, 4, "row", 1)
    assert np.array_equal(rows[:, 0], [0, 255, 255, 0])


def test_decoding_the_captured_sequence_recovers_every_projector_pixel() -> None:
    width, height = 100, 37
    rng = np.random.default_rng(0)
    albedo = rng.uniform(0.2, 1.0, (height, width))
    captures = {
        name: albedo * image / 255.0 + 0.05 + rng.normal(0, 0.01, image.shape)
        for name, image in gray_code_sequence(width, height)
    }
    dec = decode_gray(captures, lambda label: (captures[label], None), (width, height))
    assert dec.valid.all() and (dec.col_step, dec.row_step) == (1, 1)
    assert np.array_equal(dec.col, np.broadcast_to(np.arange(width), (height, width)))
    assert np.array_equal(dec.row, np.broadcast_to(np.arange(height)[:, None], (height, width)))


def test_uniform_image() -> None:
    image = uniform_image(4, 2, (1.0, 0.5, 0.0))
    assert image.shape == (2, 4, 3) and np.all(image[..., 1] == 0.5)
    with pytest.raises(ValueError):
        uniform_image(4, 2, (2.0, 0, 0))


@pytest.fixture
def projector():
    pytest.importorskip("pygame")
    from drivers.projectors.pygame_display import PygameProjector

    proj = PygameProjector(display=0, size=(64, 48), fullscreen=False)
    yield proj
    proj.close()


def test_pygame_projector_shows_patterns_pixel_exactly(projector) -> None:
    for _, pattern in gray_code_sequence(64, 48)[:4]:
        projector.show(pattern)
        assert np.array_equal(projector.shown(), np.repeat(pattern[:, :, None], 3, axis=2))
    projector.show(uniform_image(64, 48, (1.0, 0.0, 0.5)))
    assert tuple(projector.shown()[10, 10]) == (255, 0, 128)
    projector.blank()
    assert not projector.shown().any()
    assert projector.describe()["video_driver"] == "dummy"


def test_pygame_projector_rejects_wrong_sizes_and_values(projector) -> None:
    with pytest.raises(RigError, match="display is 64x48"):
        projector.show(np.zeros((10, 10)))
    with pytest.raises(RigError, match="outside"):
        projector.show(np.full((48, 64), 2.0))


def test_pygame_missing_display_index() -> None:
    pytest.importorskip("pygame")
    from drivers.projectors.pygame_display import PygameProjector

    with pytest.raises(RigError, match="display 5 does not exist"):
        PygameProjector(display=5)
