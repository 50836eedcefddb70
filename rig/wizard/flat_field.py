"""The flat-field step: frames of a diffuse white card filling the frame under the rig's own
light, at several positions, fitted to the lens's fall-off (:mod:`calibration.flat_field`).

A device that can put a card in front of its camera (``WhiteCardSource``: the simulator)
does it itself; otherwise the person holds the card (or an opal diffuser over the lens) and
says how far it is. Each position is a frame with the light off (room light, dark level)
and one under the illumination, subtracted.
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from calibration.flat_field import FlatField, card_shading, fit_flat_field
from core.errors import RigError
from drivers.protocols import Camera
from rig.capture.devices import RigDevices, device_errors
from rig.profile import Profile
from rig.wizard.common import Ask, halve_exposure, set_light, step, today

SATURATION_RETRIES = 5
DEMOSAIC = "linear"  # the fit averages blocks of pixels: the demosaic's detail is moot
SATURATION = 0.98


@dataclass(frozen=True)
class CardGeometry:
    """Where the card is: ``distance_m`` along the camera's axis, the light at
    ``light_offset_m`` (camera frame), the camera's ``focal_px``; or None for an opal diffuser
    over the lens (lit evenly)."""

    distance_m: float
    light_offset_m: Sequence[float]
    focal_px: float

    def shading(self, width: int, height: int) -> np.ndarray:
        return card_shading(width, height, self.focal_px, self.distance_m, self.light_offset_m)

    def describe(self) -> str:
        offset = ", ".join(f"{v:g}" for v in self.light_offset_m)
        return (
            f"card at {self.distance_m:g} m, light at ({offset}) m, focal {self.focal_px:g} px"
        )


def decode_card(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A white card RAW frame -> (linear RGB (H, W, 3), unsaturated mask (H, W))."""
    from reconstruct.frames.decode import decode_raw

    rgb, saturated = decode_raw(path, DEMOSAIC, SATURATION)
    return rgb.astype(float), ~saturated


def fit_card_frames(
    lit: Sequence[Path],
    dark: Sequence[Path],
    geometry: CardGeometry | None,
    details: dict[str, Any],
) -> FlatField:
    """The flat field of white card RAW files (each minus the mean of the ``dark`` ones)."""
    if not lit:
        raise RigError("no white card frames given", "pass the RAW files of the white card")
    dark_rgb = np.mean([decode_card(p)[0] for p in dark], axis=0) if dark else 0.0
    images, valid = [], []
    for path in lit:
        rgb, ok = decode_card(path)
        images.append(rgb - dark_rgb)
        valid.append(ok)
    height, width = images[0].shape[:2]
    shading = geometry.shading(width, height) if geometry is not None else None
    where = geometry.describe() if geometry is not None else "opal diffuser over the lens"
    return fit_flat_field(
        images, valid, shading, "white card" if geometry else "diffuser",
        {**details, "geometry": where},
    )


class _Shooter:
    """Frames of the card into a temporary folder, the exposure halved when it clips."""

    def __init__(self, camera: Camera) -> None:
        self.camera = camera
        self.tmp = tempfile.TemporaryDirectory(prefix="rig-flat-")
        self.shots = 0

    def pair(self, switch: Callable[[str | None], None], illumination: str) -> tuple[Path, Path]:
        """(lit, dark) RAW files at one exposure, the lit one unsaturated in the centre."""
        for _ in range(SATURATION_RETRIES):
            switch(illumination)
            lit = self._shoot()
            _, ok = decode_card(lit.paths[0])
            h, w = ok.shape
            if ok[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4].all():
                switch(None)
                return Path(lit.paths[0]), Path(self._shoot().paths[0])
            halve_exposure(self.camera, lit.exposure_s, "white card")
        raise RigError("the white card stays saturated", "move the card further from the light")

    def _shoot(self) -> Any:
        self.shots += 1
        with device_errors("camera", "camera", "photograph the white card"):
            return self.camera.capture(Path(self.tmp.name), f"flat{self.shots:03d}")


def measure_flat_field(
    args: argparse.Namespace,
    profile: Profile,
    devices: RigDevices,
    ask: Ask | None,
    console: Console,
) -> tuple[FlatField, dict[str, Any]]:
    """The flat-field step: (the fitted flat field, its provenance)."""
    illumination = profile.plan.illuminations[0]
    positions = args.flat_field_positions
    lit: list[Path] = []
    dark: list[Path] = []
    shooters: list[_Shooter] = []
    source = devices.white_card_source
    try:
        geometry: CardGeometry | None = None
        if source is not None:
            for position in range(positions):
                with device_errors("rig", "white card", "set up the white card"):
                    card = source.white_card(position)
                try:
                    light = card.light

                    def switch(name: str | None, light: Any = light) -> None:
                        light.off() if name is None else light.set_levels(
                            profile.illuminations[name]
                        )

                    shooters.append(_Shooter(card.camera))
                    pair = shooters[-1].pair(switch, illumination)
                finally:
                    card.close()
                lit.append(pair[0])
                dark.append(pair[1])
                geometry = CardGeometry(card.distance_m, card.light_offset_m, card.focal_px)
                console.print(f"flat field: {card.description}", highlight=False)
        else:
            geometry = _person_geometry(args, profile, ask)
            shooters.append(_Shooter(devices.camera))
            for position in range(positions):
                step(
                    ask,
                    console,
                    f"flat field {position + 1}/{positions}: hold the white card (or the opal "
                    "diffuser) filling the frame, facing the camera; move it a little between "
                    "positions",
                )
                pair = shooters[-1].pair(
                    lambda name: set_light(devices, profile, name), illumination
                )
                lit.append(pair[0])
                dark.append(pair[1])
        flat = fit_card_frames(lit, dark, geometry, {"illumination": illumination})
    finally:
        for shooter in shooters:
            shooter.tmp.cleanup()
    camera = devices.camera.describe() if devices.camera is not None else {}
    provenance = {
        "source": f"white card, {positions} positions, rig calibrate wizard",
        "device": camera.get("model"),
        "serial": camera.get("serial"),
        "date": today(),
        "notes": f"{flat.details.get('geometry')}; corner gain "
        + ", ".join(f"{c} {g:.3f}" for c, g in zip("RGB", flat.corner_gain(), strict=True)),
    }
    return flat, provenance


def _person_geometry(
    args: argparse.Namespace, profile: Profile, ask: Ask | None
) -> CardGeometry | None:
    """The card's distance and the camera's focal length, from the flags or asked."""
    if args.flat_field_diffuser:
        return None
    distance, focal = args.card_distance_m, args.focal_px
    if ask is not None:
        if distance is None:
            distance = _number(ask("flat field: card-to-camera distance in m: "), "distance")
        if focal is None:
            focal = _number(ask("flat field: the camera's focal length in pixels: "), "focal")
    if distance is None or focal is None:
        raise RigError(
            "the flat field needs --card-distance-m and --focal-px with --yes",
            "give the card's distance and the focal length in pixels (or --flat-field-diffuser "
            "for an opal diffuser over the lens, or --skip-flat-field)",
        )
    offset = profile.light_mount.offset_m or (0.0, 0.0, 0.0)
    return CardGeometry(distance, tuple(float(v) for v in offset), focal)


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError as exc:
        raise RigError(f"flat field {what} {text!r} is not a number", "enter a number") from exc
    if not value > 0:
        raise RigError(f"flat field {what} {value:g}", "give a positive number")
    return value
