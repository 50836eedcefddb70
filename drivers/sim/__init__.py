"""The simulated rig (``driver: sim``): a virtual scene rendered with the one forward model,
written as real Bayer DNGs, so every command runs end to end with no hardware."""

from drivers.sim.camera import SensorConfig, SimCamera
from drivers.sim.light import SimLight
from drivers.sim.projector import SimProjector
from drivers.sim.rig import SimRig
from drivers.sim.scene import SCENES, Scene, make_scene
from drivers.sim.spectrometer import SimSpectrometer
from drivers.sim.trajectory import TrajectoryConfig

__all__ = [
    "SCENES",
    "Scene",
    "SensorConfig",
    "SimCamera",
    "SimLight",
    "SimProjector",
    "SimRig",
    "SimSpectrometer",
    "TrajectoryConfig",
    "make_scene",
]
