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

from core import labels
from drivers.projectors import patterns
from rig.profile import Plan

KINDS = ("ambient", "illumination", "pattern")


@dataclass(frozen=True)
class FrameSpec:
    """One planned frame: its fixed number, its view and what lights the scene."""

    frame: int
    view: int
    label: str  # illumination name or a core.labels label (ambient, structured light)
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


def pattern_image(pattern: str, width: int, height: int) -> np.ndarray:
    """The (height, width) uint8 image of a structured-light label
    (:func:`core.labels.structured_light_labels`), made when it is shown (a full sequence at
    projector resolution need not sit in memory)."""
    if labels.is_reference(pattern):
        white = pattern.removeprefix("sl-") == labels.WHITE
        return np.full((height, width), 255 if white else 0, dtype=np.uint8)
    pid = labels.parse_pattern_id(pattern)
    if pid is None:
        raise ValueError(f"{pattern!r} is no structured-light pattern label")
    return patterns.gray_code_image(width, height, pid.axis, pid.bit, pid.inverse)


def frame_list(plan: Plan, projector_size: tuple[int, int] | None = None) -> list[FrameSpec]:
    """Every frame of the session in capture order: per view the optional ambient frame,
    then each illumination, then the structured-light patterns; each tagged with the
    projector placement of its view when the plan moves the projector on its own."""
    sequence: list[str] = []
    if plan.structured_light is not None and plan.structured_light.gray_code:
        if projector_size is None:
            raise ValueError("a structured-light plan needs the projector's size")
        sequence = labels.structured_light_labels(*projector_size)
    frames: list[FrameSpec] = []
    for view in range(plan.views):
        per_view = [(labels.AMBIENT, "ambient")] if plan.ambient else []
        per_view += [(name, "illumination") for name in plan.illuminations]
        per_view += [(pattern, "pattern") for pattern in sequence]
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
