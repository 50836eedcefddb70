"""The white reference of step 4: set up by a device that can (the simulator's chart) or
placed by the person at a distance they measure; photographed light by light."""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from calibration.grid import DEFAULT_GRID
from calibration.spectra import resample
from core.errors import RigError
from drivers.protocols import Camera
from rig.capture.devices import RigDevices, device_errors
from rig.profile import Profile
from rig.wizard.common import Ask, halve_exposure, set_light
from rig.wizard.reference_raw import region_rgb

SATURATION_RETRIES = 5


class Reference:
    """The white reference as the camera sees it: linear mean R, G, B in a region."""

    def __init__(
        self,
        camera: Camera,
        light_setter: Callable[[str | None], None],
        distance_m: float,
        reflectance: np.ndarray,
        description: str,
        region: tuple[int, int, int, int] | None,
        closer: Callable[[], None],
    ) -> None:
        self.camera = camera
        self.set_light = light_setter
        self.distance_m = distance_m
        self.reflectance = reflectance
        self.description = description
        self.region = region
        self._close = closer
        self._tmp = tempfile.TemporaryDirectory(prefix="rig-wizard-")
        self._shots = 0
        self._ambient: np.ndarray | None = None

    def _shoot(self) -> np.ndarray:
        for _ in range(SATURATION_RETRIES):
            self._shots += 1
            with device_errors("camera", "camera", "photograph the white reference"):
                frame = self.camera.capture(Path(self._tmp.name), f"ref{self._shots:03d}")
            rgb, saturated = region_rgb(Path(frame.paths[0]), self.region)
            if not saturated:
                return rgb / (frame.exposure_s * frame.iso / 100.0)
            halve_exposure(self.camera, frame.exposure_s, "white reference")
        raise RigError("the white reference stays saturated", "move the light further away")

    def photograph(self, illumination: str) -> np.ndarray:
        """Linear R, G, B of the reference under ``illumination``, room light subtracted."""
        if self._ambient is None:
            self.set_light(None)
            self._ambient = self._shoot()
        self.set_light(illumination)
        lit = self._shoot()
        self.set_light(None)
        return lit - self._ambient

    def close(self) -> None:
        self._tmp.cleanup()
        self._close()


def open_reference(
    args: argparse.Namespace, profile: Profile, devices: RigDevices, ask: Ask | None
) -> Reference:
    """The reference set-up: the one a device sets up itself when it can, else the person
    places a white tile facing the light and says how far."""
    region = parse_region(args.reference_region)
    source = devices.white_reference_source
    if source is not None:
        with device_errors("rig", "white reference", "set up the white reference"):
            own = source.white_reference(args.reference_distance_m, region)
        light = own.light

        def switch(name: str | None) -> None:
            light.off() if name is None else light.set_levels(profile.illuminations[name])

        if args.reference_reflectance == "auto" and own.reflectance is not None:
            reflectance, description = own.reflectance, own.description
        else:
            reflectance, description = reflectance_of(args.reference_reflectance)
        return Reference(
            own.camera, switch, own.distance_m, reflectance, description, own.region, own.close
        )
    distance = args.reference_distance_m
    if distance is None:
        if ask is None:
            raise RigError(
                "--reference-distance-m is needed with --yes",
                "measure the light-to-reference distance in metres and pass it",
            )
        answer = ask(
            "4/5 place the white reference facing the light, fill the centre "
            "of the frame, and enter the light-to-reference distance in m: "
        )
        try:
            distance = float(answer)
        except ValueError as exc:
            raise RigError(
                f"reference distance {answer!r} is not a number",
                "enter metres, e.g. 0.5, or pass --reference-distance-m",
            ) from exc
    if distance <= 0:
        raise RigError(f"reference distance {distance} m", "give a positive distance in metres")
    reflectance, description = reflectance_of(args.reference_reflectance)
    return Reference(
        devices.camera,
        lambda name: set_light(devices, profile, name),
        distance,
        reflectance,
        description,
        region,
        lambda: None,  # the wizard closes the devices
    )


def reflectance_of(value: str) -> tuple[np.ndarray, str]:
    """A flat reflectance from a number, or a measured one from a CSV (on the grid)."""
    if value == "auto":
        return np.full(DEFAULT_GRID.size, 0.99), "flat 0.99 (default)"
    try:
        flat = float(value)
    except ValueError:
        from calibration.importers import read_spectrum

        spectrum = read_spectrum(value)
        values = spectrum.column(None, "light")
        return resample(spectrum.wavelengths_nm, values, DEFAULT_GRID, source=value), value
    if not 0 < flat <= 1:
        raise RigError(f"--reference-reflectance {value}", "give a reflectance in (0, 1] or a CSV")
    return np.full(DEFAULT_GRID.size, flat), f"flat {flat:g}"


def parse_region(text: str | None) -> tuple[int, int, int, int] | None:
    """``--reference-region X0,Y0,X1,Y1`` in pixels."""
    if text is None:
        return None
    try:
        x0, y0, x1, y1 = (int(v) for v in text.split(","))
    except ValueError as exc:
        raise RigError(f"--reference-region {text!r}", "write X0,Y0,X1,Y1 in pixels") from exc
    return x0, y0, x1, y1
