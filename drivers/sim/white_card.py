"""The simulator's white card: the ``card`` scene filling the frame of a one-view rig with this
rig's camera (its lens fall-off included) and its light on the camera plate, the card seen
head-on and slid sideways between positions so its texture moves while the light's own
fall-off on it stays put."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from drivers.protocols import WhiteCard
from drivers.sim.scene import CARD_SIDE_M

if TYPE_CHECKING:
    from drivers.sim.rig import SimRig

DISTANCE_M = 0.3
SHIFT_M = 0.04  # how far the card slides between positions
FILL_MARGIN = 0.9  # the frame's corners stay this fraction inside the card's edge


def card_distance(rig: SimRig) -> float:
    """The distance at which the card, slid by :data:`SHIFT_M`, still fills the frame."""
    intr = rig.intrinsics
    half_diagonal = math.hypot(intr.width, intr.height) / 2.0 / float(intr.K[0, 0])
    room = FILL_MARGIN * (CARD_SIDE_M / 2.0 - SHIFT_M)
    return min(DISTANCE_M, room / half_diagonal)


def white_card(rig: SimRig, position: int) -> WhiteCard:
    """A card rig like ``rig`` (camera, seed, light offset), the card at ``position``."""
    distance = card_distance(rig)
    angle = 2.0 * math.pi * position / 5.0
    shift = 0.0 if position == 0 else SHIFT_M
    target = [shift * math.cos(angle), shift * math.sin(angle), 0.0]
    offset = rig.light_offset if rig.light_offset is not None else (0.0, 0.0, 0.0)
    light_offset = (float(offset[0]), float(offset[1]), float(offset[2]))
    config = {
        "scene": "card",
        "views": 1,
        "light_offset_m": list(light_offset),
        "light_diameter_m": rig.light_diameter_m,
        "camera": dict(rig.reference_camera),
        "trajectory": {"elevations_deg": [90.0], "radius_m": distance, "target_m": target},
    }
    card_rig = type(rig)(config, rig.seed)
    return WhiteCard(
        card_rig.camera,
        card_rig.light,
        distance,
        light_offset,
        float(card_rig.intrinsics.K[0, 0]),
        f"sim white card at {distance:.3g} m, position {position + 1}",
        card_rig.close,
    )
