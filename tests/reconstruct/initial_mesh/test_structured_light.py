"""Gray-code decoding on synthetic captures with known projector coordinates."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import RigError
from reconstruct.initial_mesh.structured_light import DecodeOptions, GrayDecoding, decode_gray
from tests.reconstruct.initial_mesh.synth import capture_stack

PROJ = (64, 48)


def decode_images(
    images: dict[str, np.ndarray],
    projector_size: tuple[int, int],
    options: DecodeOptions | None = None,
    saturated: dict[str, np.ndarray] | None = None,
) -> GrayDecoding:
    """The stage's decoder over frames held in memory (label -> image)."""
    masks = saturated or {}
    return decode_gray(
        images, lambda label: (images[label], masks.get(label)), projector_size, options
    )


def _score(dec, truth: np.ndarray, truly_lit: np.ndarray) -> tuple[float, float]:
    """(fraction of decoded pixels exactly right, fraction of truly lit pixels decoded)."""
    got = np.stack([dec.col * dec.col_step, dec.row * dec.row_step], axis=-1)
    exact = np.all(got == truth // [dec.col_step, dec.row_step] * [dec.col_step, dec.row_step],
                   axis=-1)
    valid = dec.valid & truly_lit
    return float(exact[valid].mean()), float(valid.sum() / truly_lit.sum())


@pytest.mark.parametrize("seed,curved,colour", [(0, False, False), (1, True, True),
                                                 (2, True, True)])
def test_decoding_recovers_projector_pixels(seed: int, curved: bool, colour: bool) -> None:
    images, truth, truly_lit = capture_stack(seed, proj=PROJ, curved=curved, colour=colour)
    dec = decode_images(images, PROJ)
    assert (dec.col_step, dec.row_step) == (1, 1)  # every bit resolved at ~2 px per stripe
    exact, coverage = _score(dec, truth, truly_lit)
    assert exact >= 0.99
    assert coverage >= 0.6
    # pixels the projector does not light are (almost) never trusted
    assert dec.valid[~truly_lit].mean() < 0.05


def test_shadow_and_saturation_are_rejected() -> None:
    images, truth, truly_lit = capture_stack(3, proj=PROJ, ambient=0.4, noise=0.005)
    sat = {k: v.max(axis=-1) >= 0.999 for k, v in images.items()}
    hot = np.zeros(truth.shape[:2], bool)
    hot[10:20, 60:80] = True
    sat["gray-col-02"] = sat["gray-col-02"] | hot
    dec = decode_images(images, PROJ, saturated=sat)
    assert not dec.valid[hot].any()
    assert dec.rejected["saturated"] >= hot.sum() - 5
    shadow = ~truly_lit
    assert dec.valid[shadow].mean() < 0.01
    assert _score(dec, truth, truly_lit)[0] >= 0.99


def test_unresolvable_fine_bits_are_dropped() -> None:
    # projector pixels 4x smaller than camera pixels: the finest two bits blur to grey
    images, truth, truly_lit = capture_stack(4, proj=(256, 192), blur=1.0)
    dec = decode_images(images, (256, 192))
    assert dec.col_step >= 2 and dec.row_step >= 2
    exact, coverage = _score(dec, truth, truly_lit)
    assert exact >= 0.99 and coverage >= 0.5
    strict = decode_images(images, (256, 192), DecodeOptions(auto_bits=False))
    assert strict.valid.sum() < dec.valid.sum()


def test_incomplete_sequence_names_the_missing_frame() -> None:
    images, _, _ = capture_stack(5, proj=PROJ)
    del images["gray-row-02-inv"]
    with pytest.raises(RigError, match="gray-row-02-inv"):
        decode_images(images, PROJ)
