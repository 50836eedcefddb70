"""Frame labels and Gray code: every label written parses back, every code decodes back."""

from __future__ import annotations

import numpy as np
import pytest

from core.graycode import bit_count, gray_decode, gray_encode, stripe
from core.labels import (
    AMBIENT,
    REFERENCES,
    PatternId,
    is_reserved,
    is_structured,
    parse_pattern_id,
    pattern_label,
    structured_light_labels,
)


def test_pattern_labels_round_trip() -> None:
    for axis in ("col", "row"):
        for bit in (0, 7, 12):
            for inverse in (False, True):
                pid = PatternId(axis, bit, inverse)
                assert parse_pattern_id(pid.label) == pid
                assert pid.label == pattern_label(axis, bit, inverse)
    assert pattern_label("col", 3, True) == "gray-col-03-inv"  # the manifest's spelling


def test_the_reader_accepts_both_axis_spellings_and_the_sl_prefix() -> None:
    assert parse_pattern_id("gray-col-03-inv") == parse_pattern_id("gray-x-03-inv")
    assert parse_pattern_id("sl-gray-col-03-inv") == parse_pattern_id("gray-col-03-inv")
    assert parse_pattern_id("gray-y-10") == PatternId("row", 10, False)
    assert parse_pattern_id("LED1") is None and parse_pattern_id("gray-z-01") is None
    assert is_structured("white") and is_structured("sl-black") and not is_structured("red")
    assert not is_structured(AMBIENT)
    with pytest.raises(ValueError):
        pattern_label("x", 0, False)


def test_sequence_labels_cover_every_bit_of_both_axes() -> None:
    labels = structured_light_labels(100, 37)
    assert tuple(labels[:2]) == REFERENCES
    pattern_labels = labels[2:]
    assert [getattr(parse_pattern_id(label), "label", None) for label in pattern_labels] == (
        pattern_labels
    )
    assert len(pattern_labels) == 2 * (bit_count(100) + bit_count(37))
    assert all(is_structured(label) and is_reserved(label) for label in labels)
    assert is_reserved(AMBIENT) and not is_reserved("LED1")


def test_gray_code_round_trips_and_neighbours_differ_by_one_bit() -> None:
    values = np.arange(1 << 12, dtype=np.int64)
    codes = gray_encode(values)
    flips = codes[1:] ^ codes[:-1]
    assert np.all((flips & (flips - 1)) == 0) and np.all(flips > 0)
    assert np.array_equal(gray_decode(codes), values)
    big = np.array([2**40 + 12345, 2**62 - 1], dtype=np.int64)
    assert np.array_equal(gray_decode(gray_encode(big)), big)


@pytest.mark.parametrize("size", [1, 2, 7, 64, 100])
def test_stripes_spell_each_index_gray_code(size: int) -> None:
    bits = bit_count(size)
    code = np.zeros(size, dtype=np.int64)
    for bit in range(bits):
        code = (code << 1) | stripe(size, bit)
    assert np.array_equal(gray_decode(code), np.arange(size))
    with pytest.raises(ValueError):
        stripe(size, bits)
    with pytest.raises(ValueError):
        bit_count(0)
