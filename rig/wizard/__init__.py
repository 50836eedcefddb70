"""`rig calibrate wizard`: guided spectral calibration of a rig, step by step.

1. spectrometer dark reference; 2. each illumination's SPD (measured, or imported from a
file), plotted (:mod:`.lights`); 3. camera sensitivity (built-in or imported CSV,
:mod:`.camera`); 4. radiometric scale from a photograph of a white reference of known
reflectance at a measured distance facing the light (:mod:`.scale`, :mod:`.reference`);
5. illumination selection report (:mod:`.selection`). When the profile names a
``calibration.flat_field`` entry, a flat-field step photographs a white card filling the frame
at several positions and stores the lens's fall-off under that name (:mod:`.flat_field`).
Every step is scriptable with flags (``--yes``).

A device that can set up a white reference itself (``WhiteReferenceSource``: the simulator's
ColorChecker chart, seen head-on with the light at the camera) replaces the person's tile;
one that can put a white card in front of its camera (``WhiteCardSource``) replaces the
person's card.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from core.errors import RigError
from rig.cliargs import SEED_MAX, number

# calibration.defaults.camera_names() (it loads colour-science), repeated so that the `rig`
# parser stays light; a test keeps them equal.
BUILTIN_CAMERAS = ("Canon EOS 5D Mark II", "Nikon 5100", "Sigma SD Merrill")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Measure the rig's spectra step by step and write a calibration store: (1) dark "
        "references, (2) each illumination's SPD, (3) the camera sensitivity, (4) the "
        "radiometric scale from a white reference at a measured distance, (5) an illumination "
        "selection report. Every prompt has a flag; --yes runs without prompts."
    )
    parser.add_argument("--profile", default="sim", help="rig profile (default: sim)")
    parser.add_argument(
        "--store",
        metavar="DIR",
        help="calibration store to write (default "
        "$SPECTRAL_RIG_STORE or ~/.local/share/spectral-rig/calibration)",
    )
    parser.add_argument("--yes", "-y", action="store_true", help="no prompts; use the flags")
    parser.add_argument("--seed", type=number(int, min=0, max=SEED_MAX), default=0,
                        help="simulated rig seed")
    parser.add_argument(
        "--import",
        dest="imports",
        action="append",
        default=[],
        metavar="ILLUMINATION=FILE",
        help="import this illumination's SPD from a spectrometer export "
        "instead of measuring it (repeatable)",
    )
    camera = parser.add_mutually_exclusive_group()
    camera.add_argument(
        "--camera", help=f"built-in sensitivity ({', '.join(BUILTIN_CAMERAS)})"
    )
    camera.add_argument(
        "--camera-file", metavar="CSV", help="measured sensitivity wavelength_nm,R,G,B"
    )
    parser.add_argument(
        "--reference-distance-m", type=number(float, above=0, max=100),
        help="light to white reference, metres"
    )
    parser.add_argument(
        "--reference-reflectance",
        default="auto",
        metavar="VALUE|FILE",
        help="white reference reflectance: a number (flat) or a CSV "
        "(default: 0.99, or the sim chart's white patch)",
    )
    parser.add_argument(
        "--reference-region",
        metavar="X0,Y0,X1,Y1",
        help="pixel box on the reference (default: a central square)",
    )
    parser.add_argument(
        "--skip-scale",
        action="store_true",
        help="store relative SPDs (the reconstruction then has no absolute scale)",
    )
    parser.add_argument("--noise", type=number(float, min=0, max=1), default=0.01,
                        help="selection noise (fraction)")
    flat = parser.add_argument_group(
        "flat field (when the profile names calibration.flat_field)"
    )
    flat.add_argument("--skip-flat-field", action="store_true", help="leave the flat field out")
    flat.add_argument(
        "--flat-field-positions", type=number(int, min=1, max=100), default=4, metavar="N",
        help="white card positions to average (default 4)",
    )
    flat.add_argument("--card-distance-m", type=number(float, above=0, max=100),
                      help="camera to white card, metres")
    flat.add_argument("--focal-px", type=number(float, above=0, max=1e6),
                      help="the camera's focal length in pixels")
    flat.add_argument(
        "--flat-field-diffuser", action="store_true",
        help="an opal diffuser over the lens instead of a card (evenly lit: no geometry)",
    )
    parser.add_argument(
        "--plots", metavar="DIR", help="where to write PNG plots (default STORE/plots)"
    )


def run(args: argparse.Namespace) -> int:
    from calibration import defaults
    from calibration.grid import DEFAULT_GRID
    from calibration.spectra import resample
    from calibration.store import CalibrationStore
    from rig.capture.devices import open_devices
    from rig.console import console as plain_console
    from rig.profile import load_profile
    from rig.wizard.camera import choose_camera
    from rig.wizard.common import Ask
    from rig.wizard.flat_field import measure_flat_field
    from rig.wizard.lights import measure_lights, parse_imports, plot_light
    from rig.wizard.reference import parse_region
    from rig.wizard.scale import scale_lights
    from rig.wizard.selection import selection_report

    console = plain_console(stderr=True)
    ask: Ask | None = None if args.yes else console.input
    profile = load_profile(args.profile)
    store_root = Path(args.store).expanduser() if args.store else _default_store()
    plots = Path(args.plots) if args.plots else store_root / "plots"
    imports = parse_imports(args.imports, profile)
    parse_region(args.reference_region)  # bad flags fail before any measurement
    if args.camera:
        defaults.camera_source_description(args.camera)
    flat_entry = None if args.skip_flat_field or profile.calibration is None else (
        profile.calibration.flat_field
    )
    if args.flat_field_positions < 1:
        raise RigError(
            f"--flat-field-positions {args.flat_field_positions}", "give at least 1 position"
        )
    kinds = ("camera", "light", "projector") + (
        ("spectrometer",) if len(imports) < len(profile.plan.illuminations) else ()
    )
    devices = open_devices(profile, args.seed, ask, kinds)
    try:
        if args.yes and not args.skip_scale and args.reference_distance_m is None:
            if devices.white_reference_source is None:
                raise RigError(
                    "--reference-distance-m is needed with --yes",
                    "measure the light-to-reference distance in metres and pass it "
                    "(or --skip-scale)",
                )
        lights = measure_lights(profile, devices, imports, ask, console)
        camera_name, camera_w, camera_rgb, camera_prov = choose_camera(
            args, profile, devices, ask
        )
        camera_grid = resample(camera_w, camera_rgb, DEFAULT_GRID, source=camera_name)
        if args.skip_scale:
            console.print("radiometric scale skipped: SPDs stay relative", style="yellow")
        else:
            scale_lights(args, profile, devices, lights, camera_grid, ask, console)
        flat = None
        if flat_entry is not None:
            flat = measure_flat_field(args, profile, devices, ask, console)
    finally:
        devices.close()
    store = CalibrationStore(store_root)
    store.add_camera(camera_name, camera_w, camera_rgb, camera_prov)
    if flat is not None and flat_entry is not None:
        entry = store.add_flat_field(flat_entry, *flat)
        corner = ", ".join(f"{g:.3f}" for g in flat[0].corner_gain())
        console.print(
            f"stored flat field '{entry.name}' v{entry.version} (corner gain R, G, B "
            f"{corner}); decode divides the frames by it",
            style="green",
        )
    for light in lights:
        values = light.values * (light.scale or 1.0)
        entry = store.add_light(light.entry, light.wavelengths, values, light.provenance)
        plot_light(light, values, plots, entry.version)
    console.print(
        f"stored camera '{camera_name}' and {len(lights)} light SPDs in {store.root}",
        style="green",
    )
    selection_report(
        {lt.name: lt.on_grid() * (lt.scale or 1.0) for lt in lights},
        camera_grid,
        args.noise,
        plots,
        console,
    )
    return 0


def _default_store() -> Path:
    from calibration.store import default_store_path

    return default_store_path()
