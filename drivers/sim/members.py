"""The devices of one :class:`~drivers.sim.rig.SimRig`: the plain simulated devices plus the
optional capabilities (:mod:`drivers.protocols`) the rig gives every one of them — it moves
itself, knows its truth, sets up a white reference and a white card — so a plan finds them
by type."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from drivers.protocols import WhiteCard, WhiteReference
from drivers.sim.camera import SimCamera
from drivers.sim.light import SimLight
from drivers.sim.projector import SimProjector
from drivers.sim.spectrometer import SimSpectrometer

if TYPE_CHECKING:
    from drivers.sim.rig import SimRig


class RigMember:
    """SelfPositioning, GroundTruthSource, WhiteReferenceSource and WhiteCardSource, answered
    by the rig."""

    rig: SimRig

    def goto_view(self, view: int) -> None:
        self.rig.goto_view(view)

    def view_directions(self) -> list[tuple[float, float]]:
        return self.rig.view_directions()

    def write_ground_truth(self, folder: Path) -> None:
        self.rig.write_ground_truth(folder)

    def white_reference(
        self, distance_m: float | None, region: tuple[int, int, int, int] | None
    ) -> WhiteReference:
        from drivers.sim.reference import chart_reference

        return chart_reference(self.rig, distance_m, region)

    def white_card(self, position: int) -> WhiteCard:
        from drivers.sim.white_card import white_card

        return white_card(self.rig, position)


class RigCamera(RigMember, SimCamera):
    """The rig's camera."""


class RigLight(RigMember, SimLight):
    """The rig's bulb."""


class RigProjector(RigMember, SimProjector):
    """The rig's projector."""


class RigSpectrometer(RigMember, SimSpectrometer):
    """The rig's spectrometer."""
