"""Step 4: the radiometric scale of every SPD from photographs of a white reference, so that
``y = s · Cᵀ diag(L) r`` with ``s = 1/d²`` holds in linear image units."""

from __future__ import annotations

import argparse

import numpy as np
from rich.console import Console
from rich.table import Table

from core.errors import RigError
from rig.capture.devices import RigDevices
from rig.profile import Profile
from rig.wizard.common import Ask
from rig.wizard.lights import MeasuredLight
from rig.wizard.reference import open_reference

MIN_SIGNAL = 1e-4  # linear units; below this the reference is not lit / not in the region
MISFIT_WARNING = 0.15


def scale_lights(
    args: argparse.Namespace,
    profile: Profile,
    devices: RigDevices,
    lights: list[MeasuredLight],
    camera: np.ndarray,
    ask: Ask | None,
    console: Console,
) -> None:
    """Step 4: s·Cᵀ diag(k·L) r = y for a white reference facing the light at d (s = 1/d²),
    solved for k per illumination by least squares over the three channels."""
    reference = open_reference(args, profile, devices, ask)
    try:
        distance = reference.distance_m
        rows = []
        for light in lights:
            measured = reference.photograph(light.name)
            predicted = camera.T @ (light.on_grid() * reference.reflectance) / distance**2
            if np.max(measured) < MIN_SIGNAL:
                raise RigError(
                    f"the white reference reads no signal under '{light.name}'",
                    "check it is lit and inside --reference-region",
                )
            k = float(measured @ predicted / (predicted @ predicted))
            # misfit relative to the brightest channel: a dim channel's ratio is mostly noise
            residual = float(np.max(np.abs(measured - k * predicted)) / np.max(k * predicted))
            light.scale = k
            light.provenance["radiometric_scale"] = k
            light.provenance["notes"] = (
                f"{light.provenance.get('notes', '')}; scaled ×{k:.4g} from a white reference "
                f"({reference.description}) at {distance:g} m, "
                f"channel misfit {100 * residual:.1f} %"
            )
            rows.append((light.name, k, measured, residual))
    finally:
        reference.close()
    table = Table(title="4/5 radiometric scale (white reference)")
    for column in ("illumination", "scale k", "measured R G B", "channel misfit"):
        table.add_column(column)
    for name, k, measured, residual in rows:
        table.add_row(
            name, f"{k:.4g}", " ".join(f"{v:.4f}" for v in measured), f"{100 * residual:.1f} %"
        )
    console.print(table)
    if any(r[3] > MISFIT_WARNING for r in rows):
        console.print(
            "channel misfit above 15 %: the camera sensitivity does not match "
            "the measured colours — measure or import the camera's sensitivity",
            style="yellow",
        )
