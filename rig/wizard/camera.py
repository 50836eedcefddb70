"""Step 3: the camera's spectral sensitivity, built in or imported."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from calibration import defaults
from calibration.grid import DEFAULT_GRID
from drivers.protocols import NamedSensitivity
from rig.capture.devices import RigDevices
from rig.profile import Profile
from rig.wizard.common import Ask, today


def choose_camera(
    args: argparse.Namespace, profile: Profile, devices: RigDevices, ask: Ask | None
) -> tuple[str, np.ndarray, np.ndarray, dict[str, Any]]:
    """Step 3: (entry name, wavelengths, RGB sensitivity, provenance)."""
    entry = profile.calibration.camera if profile.calibration is not None else "camera"
    if args.camera_file:
        from calibration.importers import read_spectrum

        spectrum = read_spectrum(args.camera_file)
        prov = {
            **dict(spectrum.metadata),
            "source": f"imported from {args.camera_file}",
            "date": today(),
        }
        return entry, spectrum.wavelengths_nm, spectrum.column(None, "camera"), prov
    camera = devices.camera
    default = (
        camera.sensitivity_name()
        if isinstance(camera, NamedSensitivity)
        else defaults.DEFAULT_CAMERA
    )
    name = args.camera or default
    if ask is not None and not args.camera:
        answer = ask(
            f"3/5 camera sensitivity — built-in ({', '.join(defaults.camera_names())}) "
            f"or a CSV path [{name}]: "
        ).strip()
        if answer and Path(answer).suffix.lower() in (".csv", ".txt"):
            args.camera_file = answer
            return choose_camera(args, profile, devices, None)
        name = answer or name
    w, rgb = defaults.camera_sensitivity_native(name)
    notes = f"built-in '{name}' chosen in rig calibrate wizard"
    grid = DEFAULT_GRID
    if w[0] > grid.start_nm or w[-1] < grid.stop_nm:  # as the default store does
        w, rgb = grid.wavelengths, defaults.camera_sensitivity(name, grid)
        notes += f"; extended to {grid.start_nm:g}–{grid.stop_nm:g} nm (constant extrapolation)"
    prov = {"source": defaults.camera_source_description(name), "date": today(), "notes": notes}
    return entry, w, rgb, prov
