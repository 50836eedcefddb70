"""One ``typing.Protocol`` per device kind (docs/architecture.md, Devices).

Drivers take a transport at construction (never a port string), so tests can script the
bytes. Everything that captures or switches goes through these four shapes; the simulated
rig implements the same ones.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class CapturedFrame:
    """What a camera delivered for one trigger: the file(s) as written and their metadata."""

    paths: tuple[Path, ...]
    exposure_s: float
    iso: float
    camera_serial: str
    timestamp: str  # ISO 8601, UTC
    extra: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Spectrum:
    """A spectrometer reading on the instrument's own wavelengths (not resampled)."""

    wavelengths_nm: np.ndarray
    values: np.ndarray
    integration_time_s: float
    dark_subtracted: bool
    saturated: bool = False


@runtime_checkable
class Device(Protocol):
    def describe(self) -> dict[str, Any]:
        """Model, serial, firmware, transport — recorded in the session for provenance."""
        ...

    def close(self) -> None: ...


@runtime_checkable
class LightSource(Device, Protocol):
    """A light with named channels (e.g. r, g, b, c, w) and named illuminations."""

    channels: tuple[str, ...]
    illuminations: Mapping[str, Mapping[str, float]]

    def set_levels(self, levels: Mapping[str, float]) -> None:
        """Set channel levels in [0, 1]; channels not named are switched off."""
        ...

    def set_illumination(self, name: str) -> None:
        """Switch to a named illumination and wait its settle time."""
        ...

    def off(self) -> None: ...


@runtime_checkable
class Projector(Device, Protocol):
    width: int
    height: int

    def show(self, image: np.ndarray) -> None:
        """Show an (H, W) or (H, W, 3) image, float in [0, 1] or uint8, full screen."""
        ...

    def blank(self) -> None: ...


@runtime_checkable
class Camera(Device, Protocol):
    def capture(self, out_dir: Path, stem: str) -> CapturedFrame:
        """Trigger, download the RAW file(s) into ``out_dir`` named from ``stem``."""
        ...


@runtime_checkable
class Spectrometer(Device, Protocol):
    def measure_dark(self) -> Spectrum: ...

    def measure(self) -> Spectrum:
        """One (averaged, dark-subtracted if a dark was taken) spectrum."""
        ...


# Optional capabilities (python-seabreeze's habit: a feature is a type a device may implement);
# plans test for them with ``isinstance``, never by a driver's name.


@runtime_checkable
class SelfPositioning(Protocol):
    """A device set that moves its own camera to each planned view (no person is asked)."""

    def goto_view(self, view: int) -> None: ...

    def view_directions(self) -> list[tuple[float, float]]:
        """(azimuth, elevation) in degrees of every view it can go to, seen from the object."""
        ...


@runtime_checkable
class GroundTruthSource(Protocol):
    """A device that knows the true scene it shows (mesh, reflectance, poses)."""

    def write_ground_truth(self, folder: Path) -> None:
        """Write the truth into ``folder``, the true poses as COLMAP text in ``folder/poses``."""
        ...


@dataclass
class WhiteReference:
    """A white reference set up in front of a camera, facing a light at ``distance_m``."""

    camera: Camera
    light: LightSource
    distance_m: float
    reflectance: np.ndarray | None  # on calibration's default grid; None: not known
    description: str
    region: tuple[int, int, int, int] | None  # pixel box on the reference; None: the centre
    close: Callable[[], None]


@runtime_checkable
class WhiteReferenceSource(Protocol):
    """A device that can set up a white reference by itself (no person places a tile)."""

    def white_reference(
        self, distance_m: float | None, region: tuple[int, int, int, int] | None
    ) -> WhiteReference: ...


@dataclass
class WhiteCard:
    """A diffuse white card filling a camera's frame, lit by the rig's light: the flat-field
    target. It faces the camera ``distance_m`` along its axis, the light at ``light_offset_m``
    in the camera frame, so the light's own fall-off on it is known; ``focal_px`` the camera's
    focal length in pixels."""

    camera: Camera
    light: LightSource
    distance_m: float
    light_offset_m: tuple[float, float, float]
    focal_px: float
    description: str
    close: Callable[[], None]


@runtime_checkable
class WhiteCardSource(Protocol):
    """A device that can put a white card in front of its camera by itself, at a different
    place on the card for each ``position`` (no person holds the card)."""

    def white_card(self, position: int) -> WhiteCard: ...


@runtime_checkable
class NamedSensitivity(Protocol):
    """A camera whose spectral sensitivity is a built-in one, known by name."""

    def sensitivity_name(self) -> str: ...
