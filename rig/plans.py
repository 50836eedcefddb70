"""Capture plans as generators of messages, after Bluesky's plans and RunEngine.

A plan is pure: it says *what* to do (move to a view, set the light, show a pattern, trigger)
and never touches a device, so it can be listed, counted, tested and resumed. The run loop
(``rig.capture``) interprets the messages. Frame numbers come from the plan's fixed order, so
a resumed run gives every frame the number it would have had: the manifest's frame numbers are
the resume point, and a frame already in it is never taken twice.
"""

from __future__ import annotations

from collections.abc import Collection, Iterator
from dataclasses import dataclass

import numpy as np

from drivers.projectors import patterns
from rig.profile import Plan

AMBIENT = "ambient"
KINDS = ("ambient", "illumination", "pattern")
REFERENCES = ("white", "black")  # flat projector frames of the structured-light sequence


@dataclass(frozen=True)
class FrameSpec:
    """One planned frame: its fixed number, its view and what lights the scene."""

    frame: int
    view: int
    label: str  # illumination name, "ambient", or a structured-light pattern id
    kind: str  # one of KINDS
    placement: int | None = None  # projector placement lighting the view (None: on the plate)


@dataclass(frozen=True)
class MoveTo:
    """Ask the person (or the sim) to bring the rig to a view."""

    view: int
    n_views: int


@dataclass(frozen=True)
class MoveProjector:
    """Ask the person to move the projector (only the projector) to another placement."""

    placement: int
    n_placements: int


@dataclass(frozen=True)
class SetLight:
    """Switch the light (or full-field projector colour) to an illumination; None = off."""

    illumination: str | None


@dataclass(frozen=True)
class ShowPattern:
    pattern: str


@dataclass(frozen=True)
class Trigger:
    """Capture, verify and record one planned frame."""

    spec: FrameSpec


Msg = MoveProjector | MoveTo | SetLight | ShowPattern | Trigger


def gray_code_patterns(width: int, height: int) -> list[str]:
    """Pattern ids of the structured-light sequence: the flat references ``white`` and
    ``black``, then Gray-code columns and rows (``gray-col-00``, ``gray-col-00-inv``, ... most
    significant bit first) as ``drivers.projectors.patterns`` and the decoder name them."""
    ids = list(REFERENCES)
    for axis, size in (("col", width), ("row", height)):
        for bit in range(patterns.bit_count(size)):
            ids += [patterns.pattern_id(axis, bit, False), patterns.pattern_id(axis, bit, True)]
    return ids


def pattern_image(pattern: str, width: int, height: int) -> np.ndarray:
    """The (height, width) uint8 image of a pattern id of :func:`gray_code_patterns`, made
    when it is shown (a full sequence at projector resolution need not sit in memory)."""
    if pattern in REFERENCES:
        return np.full((height, width), 255 if pattern == "white" else 0, dtype=np.uint8)
    _, axis, bit, *inverse = pattern.split("-")
    return patterns.gray_code_image(width, height, axis, int(bit), bool(inverse))


def frame_list(plan: Plan, projector_size: tuple[int, int] | None = None) -> list[FrameSpec]:
    """Every frame of the session in capture order: per view the optional ambient frame,
    then each illumination, then the structured-light patterns; each tagged with the
    projector placement of its view when the plan moves the projector on its own."""
    patterns: list[str] = []
    if plan.structured_light is not None and plan.structured_light.gray_code:
        if projector_size is None:
            raise ValueError("a structured-light plan needs the projector's size")
        patterns = gray_code_patterns(*projector_size)
    frames: list[FrameSpec] = []
    for view in range(plan.views):
        per_view = [(AMBIENT, "ambient")] if plan.ambient else []
        per_view += [(name, "illumination") for name in plan.illuminations]
        per_view += [(pattern, "pattern") for pattern in patterns]
        placement = None if plan.projector is None else plan.projector.of_view(view)
        frames += [
            FrameSpec(len(frames) + k, view, label, kind, placement)
            for k, (label, kind) in enumerate(per_view)
        ]
    return frames


def capture_plan(
    frames: list[FrameSpec], done: Collection[int], n_views: int, n_placements: int = 0
) -> Iterator[Msg]:
    """Messages for the frames not in ``done``: views with nothing left are skipped without a
    prompt, the projector is moved only when the placement changes (then the camera), and
    the light is switched only when it changes."""
    current_view: int | None = None
    placement: int | None = None
    light: str | None | bool = False  # False: unknown state
    for spec in frames:
        if spec.frame in done:
            continue
        if spec.placement is not None and spec.placement != placement:
            placement = spec.placement
            yield MoveProjector(placement, n_placements)
        if spec.view != current_view:
            current_view = spec.view
            yield MoveTo(spec.view, n_views)
        if spec.kind == "pattern":
            if light is not None:
                yield SetLight(None)
                light = None
            yield ShowPattern(spec.label)
        else:
            wanted = None if spec.kind == "ambient" else spec.label
            if wanted != light:
                yield SetLight(wanted)
                light = wanted
        yield Trigger(spec)
