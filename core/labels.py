"""Frame labels: the manifest's ``illumination`` of every frame, in one vocabulary.

A frame is lit by a named illumination of the profile, by nothing but the room (``ambient``),
or by a structured-light pattern: the flat references ``white`` and ``black`` and the Gray-code
stripes ``gray-<axis>-<bit:02d>`` with their inverses ``gray-<axis>-<bit:02d>-inv`` (axis
``col`` or ``row``, bit 0 the most significant). The reader also accepts the axis spellings
``x``/``y`` and an ``sl-`` prefix; what is written is always the canonical form.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from core.graycode import bit_count

AMBIENT = "ambient"  # a view's frame with every light off (reconstruct.frames.ambient)
WHITE = "white"
BLACK = "black"
REFERENCES = (WHITE, BLACK)  # flat projector frames of the structured-light sequence
RESERVED = (AMBIENT, *REFERENCES)  # labels that no illumination may take
GRAY_PREFIX = "gray-"
AXES = ("col", "row")
_AXIS_ALIASES = {"col": "col", "x": "col", "row": "row", "y": "row"}
_PATTERN = re.compile(r"^(?:sl-)?gray-(col|row|x|y)-(\d+)(-inv)?$")


@dataclass(frozen=True)
class PatternId:
    """One Gray-code frame: ``axis`` ``col`` or ``row``, ``bit`` (0 = MSB), ``inverse``."""

    axis: str
    bit: int
    inverse: bool

    @property
    def label(self) -> str:
        """The canonical frame label, e.g. ``gray-col-03-inv``."""
        return pattern_label(self.axis, self.bit, self.inverse)


def pattern_label(axis: str, bit: int, inverse: bool) -> str:
    """``gray-<axis>-<bit:02d>`` with ``-inv`` for the inverse pattern."""
    if axis not in AXES:
        raise ValueError(f"axis must be one of {AXES}, got {axis!r}")
    return f"{GRAY_PREFIX}{axis}-{bit:02d}" + ("-inv" if inverse else "")


def parse_pattern_id(label: str) -> PatternId | None:
    """The Gray-code pattern a label names, or None for any other label."""
    match = _PATTERN.match(label)
    if match is None:
        return None
    axis, bit, inv = match.groups()
    return PatternId(_AXIS_ALIASES[axis], int(bit), inv is not None)


def is_reference(label: str) -> bool:
    """Whether a label is a flat projector reference (``white``/``black``, maybe ``sl-``)."""
    return label.removeprefix("sl-") in REFERENCES


def is_structured(label: str) -> bool:
    """Whether a frame belongs to the structured-light sequence (Gray code or flat reference)."""
    return is_reference(label) or parse_pattern_id(label) is not None


def is_reserved(name: str) -> bool:
    """Whether a name is taken by the ambient or structured-light frames (so no illumination
    of a profile may use it)."""
    return name in RESERVED or name.startswith(GRAY_PREFIX)


def structured_light_labels(width: int, height: int) -> list[str]:
    """Labels of the structured-light sequence of a ``width`` x ``height`` projector in capture
    order: the references, then columns and rows, each bit (MSB first) followed by its
    inverse."""
    out = list(REFERENCES)
    for axis, size in zip(AXES, (width, height), strict=True):
        for bit in range(bit_count(size)):
            out += [pattern_label(axis, bit, False), pattern_label(axis, bit, True)]
    return out
