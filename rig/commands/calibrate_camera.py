"""`rig calibrate camera --from-chart`: a camera's spectral sensitivity estimated from photos of
a ColorChecker under lamps measured into the store (calibration.camera_fit), written to the
store as a new camera with how it was obtained and how well it fits.

The libraries are imported inside the handler so that building the `rig` parser stays fast.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from core.errors import RigError
from rig.cliargs import number
from rig.outpaths import output_file

if TYPE_CHECKING:
    import numpy as np

    from calibration.camera_fit import CameraFit
    from calibration.camera_prior import TrainingSet
    from calibration.store import CalibrationStore

DEFAULT_COMPONENTS = 4  # = calibration.camera_prior.DEFAULT_COMPONENTS
PRIOR_HELP = (
    "measured sensitivities the prior is learnt from: a camspec file or a folder of them (e.g. "
    "Jiang et al.'s database, camspec_database_27.txt); default: the cameras in the store"
)


def _lamps(store: CalibrationStore, names: list[str], n_photos: int) -> list[str]:
    if len(names) not in (1, n_photos):
        raise RigError(
            f"{len(names)} --lamp names for {n_photos} photos",
            "give one store light per photo, in the same order, or one for all",
        )
    known = store.names("light")
    for name in names:
        if name not in known:
            raise RigError(
                f"--lamp {name!r} is not a light in the calibration store {store.root}",
                "measure the lamp and `rig calibrate import FILE --kind light --name NAME` it; "
                f"lights in the store: {', '.join(known) or 'none'}",
            )
    return names * n_photos if len(names) == 1 else names


def _raw_patches(path: Path) -> np.ndarray:
    from reconstruct.chart import read_patches

    return read_patches(path).rgb


def _training(args: argparse.Namespace, store: CalibrationStore) -> TrainingSet:
    from calibration.camera_prior import read_camspec, training_set_from_store

    if args.prior:
        return read_camspec(args.prior)
    return training_set_from_store(store, exclude=(args.name,))


def _provenance(
    args: argparse.Namespace,
    store: CalibrationStore,
    lamps: list[str],
    fit: CameraFit,
) -> dict[str, Any]:
    from calibration.camera_prior import CHART_FIT_METHOD

    sources = args.from_chart or args.patches
    versions = [f"{n} v{store.entry(n, kind='light').version}" for n in lamps]
    training = fit.prior.training
    return {
        "method": CHART_FIT_METHOD,
        "source": f"estimated by `rig calibrate camera --from-chart` from {len(sources)} "
        f"ColorChecker {'photo' if args.from_chart else 'patch file'}(s)",
        "photos" if args.from_chart else "patch_files": [str(Path(s).resolve()) for s in sources],
        "lamps": versions,
        "chart": "ColorChecker 24, BabelColor average reflectances",
        "prior": f"{len(training.names)} cameras from {training.source}, "
        f"{fit.prior.n_components} components per channel",
        "fit": fit.summary(),
        "notes": "ESTIMATE from a chart, not a measurement: its typical error, leave-one-camera-"
        "out over measured cameras, is in bench/README.md (camera_from_chart)",
    }


def _print_fit(fit: CameraFit, names: list[str], sources: list[str]) -> None:
    from rich.table import Table

    from rig.console import console as plain_console

    console = plain_console()
    table = Table(
        title="chart fit: residual per patch (% of the photo's brightest patch, RGB angle)"
    )
    table.add_column("patch", justify="right")
    table.add_column("name")
    for p in range(len(sources)):
        table.add_column(f"photo {p + 1} %", justify="right")
        table.add_column("°", justify="right")
    err, angle = fit.patch_error_percent(), fit.patch_angle_deg()
    for i, name in enumerate(names):
        cells = [c for p in range(len(sources)) for c in (f"{err[p, i]:.2f}", f"{angle[p, i]:.2f}")]
        table.add_row(str(i + 1), name, *cells)
    console.print(table)
    for p, source in enumerate(sources):
        console.print(f"photo {p + 1}: {source}, exposure factor {fit.exposure[p]:.4g}")
    summary = fit.summary()
    console.print(
        f"residual RMS {summary['patch_error_rms_percent']} %, max "
        f"{summary['patch_error_max_percent']} %, mean angle {summary['patch_angle_mean_deg']}°; "
        f"the light varies by {summary['light_unevenness_percent']} % across the chart"
    )
    console.print(
        f"distance from the prior's mean (R, G, B): {summary['prior_distance_rgb']} "
        f"(the training cameras' median: {summary['prior_distance_training_median']}); nearest "
        f"training camera: {summary['nearest_training_camera']}"
    )


def run(args: argparse.Namespace, store: CalibrationStore) -> int:
    """The command on an opened store (`rig calibrate` opens it the way its other actions do)."""
    import numpy as np

    from calibration import defaults
    from calibration.camera_fit import fit_camera, read_patch_csv
    from calibration.camera_fit_plot import plot_camera_fit
    from calibration.camera_prior import build_prior
    from calibration.grid import DEFAULT_GRID
    from rig.console import console as plain_console

    sources: list[str] = args.from_chart or args.patches
    plot = output_file(
        Path(args.plot or f"{re.sub(r'[^A-Za-z0-9._+-]+', '_', args.name)}.chart-fit.png"), "--plot"
    )
    lamps = _lamps(store, args.lamp, len(sources))
    spds = np.stack([store.light_spd(n, DEFAULT_GRID) for n in lamps])
    prior = build_prior(_training(args, store), args.components)
    read = _raw_patches if args.from_chart else read_patch_csv
    patches = np.stack([read(Path(s)) for s in sources])
    names, chart = defaults.colorchecker_reflectances(DEFAULT_GRID)
    fit = fit_camera(patches, spds, chart, prior, white_level=args.white_level)
    _print_fit(fit, names, sources)
    entry = store.add_camera(
        args.name, DEFAULT_GRID.wavelengths, fit.sensitivity, _provenance(args, store, lamps, fit)
    )
    plot_camera_fit(fit, DEFAULT_GRID.wavelengths, f"{args.name} v{entry.version}", plot)
    console = plain_console()
    console.print(f"added camera {entry.name!r} version {entry.version} to {store.root}")
    console.print(f"plot written to {plot}")
    return 0


def add_parser(
    sub: argparse._SubParsersAction,
    common: argparse.ArgumentParser,
    handler: Callable[[argparse.Namespace], int],
) -> None:
    """The `camera` action of `rig calibrate`, run by ``handler``."""
    p = sub.add_parser(
        "camera",
        parents=[common],
        help="estimate a camera's sensitivity from photos of a ColorChecker",
        description="Estimate an unlisted camera's spectral sensitivity from RAW photos of a "
        "ColorChecker 24 under lamps measured into the store, with measured cameras as the "
        "prior, and add it to the store.",
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument(
        "--from-chart", nargs="+", metavar="RAW", help="RAW photos of the chart filling the frame"
    )
    source.add_argument(
        "--patches",
        nargs="+",
        metavar="CSV",
        help="patch values measured elsewhere: per photo a CSV of 24 linear R,G,B rows "
        "(black subtracted) in the chart's order, dark skin … black",
    )
    p.add_argument(
        "--lamp",
        nargs="+",
        required=True,
        metavar="LIGHT",
        help="the store's light entry of each photo, in order (one name: the same for all)",
    )
    p.add_argument("--name", required=True, help="the new camera's store entry name")
    p.add_argument("--prior", metavar="FILE|DIR", help=PRIOR_HELP)
    p.add_argument(
        "--components",
        type=number(int, min=1, max=1000),
        default=DEFAULT_COMPONENTS,
        help="principal components per channel in the prior",
    )
    p.add_argument(
        "--white-level",
        type=number(float, above=0, max=1e9),
        metavar="V",
        help="patch values at or above V are saturated (refused)",
    )
    p.add_argument("--plot", metavar="PNG", help="fit plot (default NAME.chart-fit.png)")
    p.set_defaults(func=handler)
