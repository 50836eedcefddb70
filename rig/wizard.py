"""`rig calibrate wizard`: guided spectral calibration of a rig, step by step.

1. spectrometer dark reference; 2. each illumination's SPD (measured, or imported from a
file), plotted; 3. camera sensitivity (built-in or imported CSV); 4. radiometric scale from a
photograph of a white reference of known reflectance at a measured distance facing the light,
so that the forward model ``y = s · Cᵀ diag(L) r`` with ``s = 1/d²`` holds in linear image
units (docs/architecture.md, Radiometry); 5. illumination selection report. Every step is
scriptable with flags (``--yes``).

On the simulated rig the white reference is the ColorChecker's white patch of the sim's
``chart`` scene, seen head-on with the light at the camera.
"""

from __future__ import annotations

import argparse
import datetime as dt
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from calibration import defaults
from calibration.grid import DEFAULT_GRID
from calibration.spectra import resample
from calibration.store import CalibrationStore
from core.errors import RigError
from drivers.protocols import Camera, LightSource, Spectrometer, Spectrum
from rig.capture.devices import RigDevices, device_errors, open_devices, open_sim
from rig.profile import Profile, load_profile

SATURATION_RETRIES = 5
AUTO_RANGE_STEPS = 20
TARGET_FILL = 0.6  # spectrometer peak as a fraction of full scale
MAX_INTEGRATION_S = 600.0
REGION_FRACTION = 0.02  # default reference region: a central square this fraction of the image
MIN_SIGNAL = 1e-4  # linear units; below this the reference is not lit / not in the region

Ask = Callable[[str], str]


@dataclass
class MeasuredLight:
    """One illumination's SPD at its measured sampling, before and after the scale."""

    name: str  # illumination name in the profile
    entry: str  # calibration store entry name
    wavelengths: np.ndarray
    values: np.ndarray  # relative (counts/s or the imported file's units) until scaled
    provenance: dict[str, Any]
    scale: float | None = None

    def on_grid(self) -> np.ndarray:
        return resample(self.wavelengths, self.values, DEFAULT_GRID, source=self.name)


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
    parser.add_argument("--seed", type=int, default=0, help="simulated rig seed")
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
        "--camera", help=f"built-in sensitivity ({', '.join(defaults.camera_names())})"
    )
    camera.add_argument(
        "--camera-file", metavar="CSV", help="measured sensitivity wavelength_nm,R,G,B"
    )
    parser.add_argument(
        "--reference-distance-m", type=float, help="light to white reference, metres"
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
    parser.add_argument("--noise", type=float, default=0.01, help="selection noise (fraction)")
    parser.add_argument(
        "--plots", metavar="DIR", help="where to write PNG plots (default STORE/plots)"
    )


def run(args: argparse.Namespace) -> int:
    console = Console(stderr=True)
    ask: Ask | None = None if args.yes else console.input
    profile = load_profile(args.profile)
    store_root = Path(args.store).expanduser() if args.store else _default_store()
    plots = Path(args.plots) if args.plots else store_root / "plots"
    imports = _parse_imports(args.imports, profile)
    _parse_region(args.reference_region)  # bad flags fail before any measurement
    if args.camera:
        defaults.camera_source_description(args.camera)
    light_spec = profile.device("light") or profile.device("projector") or {}
    if args.yes and not args.skip_scale and args.reference_distance_m is None:
        if light_spec.get("driver") != "sim":
            raise RigError(
                "--reference-distance-m is needed with --yes",
                "measure the light-to-reference distance in metres and pass it (or --skip-scale)",
            )
    kinds = ("camera", "light", "projector") + (
        ("spectrometer",) if len(imports) < len(profile.plan.illuminations) else ()
    )
    devices = open_devices(profile, args.seed, ask, kinds)
    try:
        lights = measure_lights(profile, devices, imports, ask, console)
    finally:
        devices.close()
    camera_name, camera_w, camera_rgb, camera_prov = choose_camera(args, profile, devices, ask)
    camera_grid = resample(camera_w, camera_rgb, DEFAULT_GRID, source=camera_name)
    if args.skip_scale:
        console.print("[yellow]radiometric scale skipped: SPDs stay relative[/]")
    else:
        scale_lights(args, profile, lights, camera_grid, ask, console)
    store = CalibrationStore(store_root)
    store.add_camera(camera_name, camera_w, camera_rgb, camera_prov)
    for light in lights:
        values = light.values * (light.scale or 1.0)
        entry = store.add_light(light.entry, light.wavelengths, values, light.provenance)
        _plot_light(light, values, plots, entry.version)
    console.print(
        f"[green]stored[/] camera '{camera_name}' and {len(lights)} light SPDs in {store.root}",
        highlight=False,
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


def _parse_imports(items: list[str], profile: Profile) -> dict[str, Path]:
    out = {}
    for item in items:
        name, sep, file = item.partition("=")
        if not sep or name not in profile.illuminations:
            raise RigError(
                f"--import {item!r} does not name an illumination of {profile.source}",
                f"write ILLUMINATION=FILE with one of {', '.join(profile.illuminations)}",
            )
        out[name] = Path(file)
    return out


def _entry_name(profile: Profile, illumination: str) -> str:
    if profile.calibration is not None:
        return profile.calibration.lights.get(illumination, illumination)
    return illumination


def _today() -> str:
    return dt.date.today().isoformat()


def _set_light(devices: RigDevices, profile: Profile, name: str | None) -> None:
    light = devices.light
    if light is None:
        if devices.projector is None:
            raise RigError(f"{profile.source} has no light or projector", "add devices.light")
        levels = profile.illuminations.get(name or "", {})
        rgb = np.array([levels.get(c, 0.0) for c in "rgb"])
        projector = devices.projector
        image = np.broadcast_to(rgb, (projector.height, projector.width, 3)).copy()
        with device_errors("projector", devices.names.get("projector", "?"), "show a colour"):
            projector.show(image) if name else projector.blank()
        return
    with device_errors("light", devices.names.get("light", "?"), f"switch to {name or 'off'}"):
        if name is None:
            light.off()
        else:
            light.set_levels(profile.illuminations[name])


def measure_lights(
    profile: Profile,
    devices: RigDevices,
    imports: dict[str, Path],
    ask: Ask | None,
    console: Console,
) -> list[MeasuredLight]:
    """Steps 1 and 2: per illumination, an integration time that fills the detector, a dark
    reference at that time with the light off, then the dark-subtracted SPD (or an import)."""
    spectrometer = devices.spectrometer
    if spectrometer is not None:
        _step(
            ask,
            console,
            "1/5 dark references are taken with the light off before each "
            "measurement: shade the spectrometer's input from room light",
        )
    out: list[MeasuredLight] = []
    for name in profile.plan.illuminations:
        entry = _entry_name(profile, name)
        if name in imports:
            out.append(_import_light(name, entry, imports[name]))
            console.print(f"2/5 {name}: imported from {imports[name]}", highlight=False)
            continue
        if spectrometer is None:
            raise RigError(
                f"{profile.source} has no spectrometer to measure '{name}'",
                f"add devices.spectrometer or pass --import {name}=FILE",
            )
        _step(ask, console, f"2/5 {name}: point the spectrometer at the light")
        where = ("spectrometer", devices.names.get("spectrometer", "?"), f"measure {name}")
        with device_errors(*where):
            _set_light(devices, profile, name)
            _auto_range(spectrometer)
            _set_light(devices, profile, None)
            spectrometer.measure_dark()
            _set_light(devices, profile, name)
            spectrum = spectrometer.measure()
        _set_light(devices, profile, None)
        if spectrum.saturated:
            raise RigError(
                f"spectrometer saturates on '{name}'",
                "shorten its integration time or move it away from the light",
            )
        out.append(_measured(name, entry, spectrum, spectrometer, devices))
        console.print(
            f"2/5 {name}: measured at {1000 * spectrum.integration_time_s:.4g} ms", highlight=False
        )
    return out


def _auto_range(spectrometer: Spectrometer) -> None:
    """Integration time putting the peak at ~60 % of full scale: the driver's own
    ``auto_range`` when it has one, else by measurements (proportional when the full scale is
    known, doubling up to saturation and backing off when not)."""
    own = getattr(spectrometer, "auto_range", None)
    if callable(own):
        own()
        return
    setter = getattr(spectrometer, "set_integration_time", None)
    if setter is None:
        return
    full = getattr(spectrometer, "full_scale", None) or getattr(spectrometer, "max_counts", None)
    for _ in range(AUTO_RANGE_STEPS):
        spectrum = spectrometer.measure()
        time_s = spectrum.integration_time_s
        values = np.asarray(spectrum.values, dtype=float)
        if spectrum.saturated:
            setter(time_s / 4)
            if full is None:
                return
            continue
        if full is None:
            wanted = time_s * 2
        else:
            peak = float(values.max())
            if abs(peak / (TARGET_FILL * full) - 1) < 0.2:
                return
            wanted = time_s * float(np.clip(TARGET_FILL * full / max(peak, 1.0), 0.1, 100.0))
        if wanted > MAX_INTEGRATION_S:
            setter(MAX_INTEGRATION_S)
            return
        setter(wanted)


def _measured(
    name: str, entry: str, spectrum: Spectrum, spectrometer: Spectrometer, devices: RigDevices
) -> MeasuredLight:
    """The SPD in counts/s (noise below zero clipped), with its provenance."""
    values = np.clip(np.asarray(spectrum.values, float) / spectrum.integration_time_s, 0.0, None)
    describe = spectrometer.describe()
    light = devices.light.describe() if devices.light is not None else {}
    prov = {
        "source": "measured by rig calibrate wizard",
        "device": light.get("model"),
        "serial": light.get("serial"),
        "date": _today(),
        "instrument": f"{describe.get('model', '?')} ({describe.get('serial', '?')})",
        "integration_time_ms": 1000 * spectrum.integration_time_s,
        "notes": f"counts/s, dark-subtracted={spectrum.dark_subtracted}",
    }
    return MeasuredLight(name, entry, np.asarray(spectrum.wavelengths_nm, float), values, prov)


def _import_light(name: str, entry: str, path: Path) -> MeasuredLight:
    from calibration.importers import read_spectrum

    spectrum = read_spectrum(path)
    values = spectrum.column(None, "light")
    prov = {
        **dict(spectrum.metadata),
        "source": f"imported from {path} ({spectrum.format})",
        "date": _today(),
    }
    return MeasuredLight(name, entry, spectrum.wavelengths_nm, np.asarray(values, float), prov)


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
            "date": _today(),
        }
        return entry, spectrum.wavelengths_nm, spectrum.column(None, "camera"), prov
    sim_camera = getattr(devices.sim, "sensor", None)
    default = getattr(sim_camera, "sensitivity", None) or defaults.DEFAULT_CAMERA
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
    prov = {"source": defaults.camera_source_description(name), "date": _today(), "notes": notes}
    return entry, w, rgb, prov


def scale_lights(
    args: argparse.Namespace,
    profile: Profile,
    lights: list[MeasuredLight],
    camera: np.ndarray,
    ask: Ask | None,
    console: Console,
) -> None:
    """Step 4: s·Cᵀ diag(k·L) r = y for a white reference facing the light at d (s = 1/d²),
    solved for k per illumination by least squares over the three channels."""
    reference = open_reference(args, profile, ask, console)
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
    if any(r[3] > 0.15 for r in rows):
        console.print(
            "[yellow]channel misfit above 15 %: the camera sensitivity does not match "
            "the measured colours — measure or import the camera's sensitivity[/]"
        )


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
            setter = getattr(self.camera, "set_exposure", None)
            if setter is None:
                raise RigError(
                    "the white reference is saturated",
                    "shorten the exposure (camera_settings.exposure_s) and run again",
                )
            setter(frame.exposure_s / 2)
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


def region_rgb(path: Path, region: tuple[int, int, int, int] | None) -> tuple[np.ndarray, bool]:
    """Mean of each CFA colour (R, G, B) in ``region`` of a RAW frame, in (raw − black) /
    (white − black), and whether any pixel there is saturated (no demosaicing needed)."""
    import rawpy

    with rawpy.imread(str(path)) as raw:
        values = raw.raw_image_visible.astype(np.float64)
        colours = raw.raw_colors_visible.copy()
        desc = raw.color_desc.decode()
        black = np.asarray(raw.black_level_per_channel, dtype=float)[colours]
        white = float(raw.white_level)
    height, width = values.shape
    if region is None:
        side = max(4, int(REGION_FRACTION * min(height, width)) // 2 * 2)
        region = (
            (width - side) // 2,
            (height - side) // 2,
            (width + side) // 2,
            (height + side) // 2,
        )
    x0, y0, x1, y1 = region
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise RigError(
            f"--reference-region {region} is outside the {width}x{height} image",
            "give X0,Y0,X1,Y1 inside the image",
        )
    window = (slice(y0, y1), slice(x0, x1))
    level = (values[window] - black[window]) / (white - black[window])
    letters = np.array(list(desc))[colours[window]]
    rgb = np.array([level[letters == c].mean() for c in "RGB"])
    return rgb, bool(np.any(values[window] >= white))


def open_reference(
    args: argparse.Namespace, profile: Profile, ask: Ask | None, console: Console
) -> Reference:
    """The reference set-up: on the sim a chart rig looking head-on at the white patch, with
    the light at the camera; on a real rig the person places a white tile and says how far."""
    region = _parse_region(args.reference_region)
    light_spec = profile.device("light") or profile.device("projector") or {}
    if light_spec.get("driver") == "sim":
        return _sim_reference(args, profile, region)
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
    reflectance, description = _reflectance(args.reference_reflectance)
    devices = open_devices(profile, args.seed, ask, ("camera", "light", "projector"))
    return Reference(
        devices.camera,
        lambda name: _set_light(devices, profile, name),
        distance,
        reflectance,
        description,
        region,
        devices.close,
    )


def _sim_reference(
    args: argparse.Namespace, profile: Profile, region: tuple[int, int, int, int] | None
) -> Reference:
    from drivers.sim import make_scene

    names, patches = defaults.colorchecker_reflectances(DEFAULT_GRID)
    white = next(i for i, n in enumerate(names) if n.lower().startswith("white"))
    chart = make_scene("chart")
    centre = chart.vertices[chart.patch == white].mean(axis=0)
    distance = args.reference_distance_m or 0.5
    config = {
        "scene": "chart",
        "views": 1,
        "light_offset_m": [0.0, 0.0, 0.0],
        "camera": dict(profile.sim.get("camera", {})),
        "trajectory": {
            "elevations_deg": [90.0],
            "radius_m": distance,
            "target_m": [float(c) for c in centre],
        },
    }
    sim = open_sim(config, args.seed)
    if region is None:  # the central part of the white patch (20 mm) as the sim sees it
        side = max(2, int(0.6 * sim.intrinsics.K[0, 0] * 0.020 / distance) // 2 * 2)
        cx, cy = sim.intrinsics.width // 2, sim.intrinsics.height // 2
        region = (cx - side // 2, cy - side // 2, cx + side // 2, cy + side // 2)
    light: LightSource = sim.light

    def set_light(name: str | None) -> None:
        light.off() if name is None else light.set_levels(profile.illuminations[name])

    if args.reference_reflectance == "auto":
        reflectance, description = patches[white], f"sim chart patch '{names[white]}'"
    else:
        reflectance, description = _reflectance(args.reference_reflectance)
    return Reference(sim.camera, set_light, distance, reflectance, description, region, sim.close)


def _reflectance(value: str) -> tuple[np.ndarray, str]:
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


def _parse_region(text: str | None) -> tuple[int, int, int, int] | None:
    if text is None:
        return None
    try:
        x0, y0, x1, y1 = (int(v) for v in text.split(","))
    except ValueError as exc:
        raise RigError(f"--reference-region {text!r}", "write X0,Y0,X1,Y1 in pixels") from exc
    return x0, y0, x1, y1


def selection_report(
    spds: dict[str, np.ndarray], camera: np.ndarray, noise: float, plots: Path, console: Console
) -> None:
    """Step 5: which subsets of the measured illuminations recover reflectance best."""
    from calibration.basis import default_basis
    from calibration.plots import plot_selection
    from calibration.selection import rank_illumination_sets

    _, reflectances = defaults.colorchecker_reflectances(DEFAULT_GRID)
    scores = rank_illumination_sets(
        spds,
        camera,
        reflectances,
        default_basis(DEFAULT_GRID),
        max_size=min(3, len(spds)),
        noise=noise,
    )
    table = Table(title="5/5 illumination selection (expected spectral RMSE, ColorChecker 24)")
    for column in ("illuminations", "mean RMSE", "max RMSE"):
        table.add_column(column)
    for score in scores[:5]:
        table.add_row(" + ".join(score.names), f"{score.mean_rmse:.4f}", f"{score.max_rmse:.4f}")
    console.print(table)
    path = plot_selection(
        scores,
        camera,
        spds,
        DEFAULT_GRID.wavelengths,
        plots / "illumination-selection.png",
        min(15, len(scores)),
    )
    console.print(f"plots in {path.parent}", highlight=False)


def _plot_light(light: MeasuredLight, values: np.ndarray, plots: Path, version: int) -> Path:
    from calibration.plots import plot_spectrum

    slug = "".join(c if c.isalnum() or c in "-_." else "-" for c in light.entry)
    unit = "scaled to the forward model's units" if light.scale else "relative"
    return plot_spectrum(
        light.wavelengths,
        values[:, None],
        ["power"],
        f"{light.name} ({light.entry} v{version}, {unit})",
        plots / f"spd-{slug}.v{version}.png",
    )


def _step(ask: Ask | None, console: Console, text: str) -> None:
    if ask is None:
        console.print(text, highlight=False)
    else:
        ask(f"{text} — press Enter ")
