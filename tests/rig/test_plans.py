"""Plans: fixed frame numbering, resume skipping, Gray-code patterns that decode."""

from __future__ import annotations

import numpy as np
from fakes import fake_profile

from core.labels import structured_light_labels
from rig.plans import (
    MoveTo,
    SetLight,
    ShowPattern,
    Trigger,
    capture_plan,
    frame_list,
    pattern_image,
)
from rig.profile import parse_profile


def test_frame_list_order_and_numbering() -> None:
    frames = frame_list(fake_profile(views=3).plan)
    assert [f.frame for f in frames] == list(range(12))
    assert [(f.view, f.label) for f in frames[:5]] == [
        (0, "ambient"),
        (0, "A"),
        (0, "B"),
        (0, "C"),
        (1, "ambient"),
    ]
    assert frames[0].kind == "ambient" and frames[1].kind == "illumination"


def test_capture_plan_skips_done_frames_and_finished_views() -> None:
    frames = frame_list(fake_profile(views=3, ambient=False).plan)
    done = {0, 1, 2, 3}  # view 0 complete, view 1 has frame 3 only
    msgs = list(capture_plan(frames, done, 3))
    assert msgs[0] == MoveTo(1, 3)
    triggers = [m.spec.frame for m in msgs if isinstance(m, Trigger)]
    assert triggers == [4, 5, 6, 7, 8]
    assert MoveTo(0, 3) not in msgs
    # the light is set before each trigger because the illumination changes each frame
    assert isinstance(msgs[1], SetLight) and msgs[1].illumination == "B"


def test_structured_light_labels_decode_every_column_and_row() -> None:
    width, height = 40, 24
    ids = structured_light_labels(width, height)
    assert ids[:2] == ["white", "black"]
    for axis, size in (("col", width), ("row", height)):
        bits = [i for i in ids if i.startswith(f"gray-{axis}-") and not i.endswith("-inv")]
        assert len(bits) == int(np.ceil(np.log2(size)))
        gray = np.zeros(size, dtype=int)
        for bit_id in bits:
            image = pattern_image(bit_id, width, height)
            inverse = pattern_image(bit_id + "-inv", width, height)
            line = (image[0] if axis == "col" else image[:, 0]).astype(int)
            inv = (inverse[0] if axis == "col" else inverse[:, 0]).astype(int)
            assert np.all(line + inv == 255)
            gray = (gray << 1) | (line > inv).astype(int)
        binary = gray.copy()  # Gray -> binary
        shift = gray >> 1
        while shift.any():
            binary ^= shift
            shift >>= 1
        np.testing.assert_array_equal(binary, np.arange(size))


def test_projector_plan_shows_patterns_after_colours() -> None:
    data = {
        "devices": {"projector": {"driver": "sim"}, "camera": {"driver": "sim"}},
        "illuminations": {"red": {"r": 1.0}, "rgb": {"r": 1.0, "g": 1.0, "b": 1.0}},
        "plan": {"views": 2, "structured_light": {"gray_code": True}},
    }
    plan = parse_profile(data, "p.yaml").plan
    frames = frame_list(plan, (16, 8))
    per_view = 2 + len(structured_light_labels(16, 8))
    assert len(frames) == 2 * per_view
    msgs = list(capture_plan(frames, set(), 2))
    shows = [m.pattern for m in msgs if isinstance(m, ShowPattern)]
    assert shows[:3] == ["white", "black", "gray-col-00"]
    assert SetLight(None) in msgs
