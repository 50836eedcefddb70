"""`rig calibrate`: spectral calibration store, basis and illumination selection.

The calibration library (NumPy, colour-science, matplotlib) is imported inside the handlers so
that building the `rig` parser stays fast for every other command.
"""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

from core.errors import RigError
from rig import wizard
from rig.cliargs import number
from rig.commands import calibrate_camera, calibrate_flat_field
from rig.outpaths import output_dir, output_file

if TYPE_CHECKING:
    import numpy as np

    from calibration.store import CalibrationStore

ENV_STORE = "SPECTRAL_RIG_STORE"  # = calibration.store.ENV_STORE
FORMATS = ("auto", "csv", "oceanview", "spectrawiz")  # = calibration.importers.FORMATS
DEFAULT_CAMERA = "Canon EOS 5D Mark II"  # = calibration.defaults.DEFAULT_CAMERA


def _store_root(args: argparse.Namespace) -> Path:
    from calibration.store import default_store_path

    if args.store:
        return output_dir(Path(args.store), "--store")
    # `$SPECTRAL_RIG_STORE` naming a file gets the same one line as `--store` would
    return output_dir(default_store_path(), f"${ENV_STORE}" if os.environ.get(ENV_STORE) else
                      "the default store")


def _store(args: argparse.Namespace, *, must_exist: bool = True) -> CalibrationStore:
    from calibration.store import CalibrationStore

    root = _store_root(args)
    if must_exist and not (root / "index.yaml").exists():
        where = f"`rig calibrate init-store {root}`" if _can_hold_a_store(root) else (
            "`rig calibrate init-store NEW_FOLDER`"
        )
        raise RigError(
            f"no calibration store at {root}",
            f"create one with {where} (or pass --store DIR / set ${ENV_STORE})",
        )
    return CalibrationStore(root)


def _can_hold_a_store(root: Path) -> bool:
    """Whether ``init-store`` could make ``root`` a store: a new folder, or an empty one, that
    this user may write (the nearest existing folder on the way)."""
    if root.is_dir():
        return not any(root.iterdir()) and os.access(root, os.W_OK | os.X_OK)
    if root.exists():
        return False
    parent = next((p for p in root.parents if p.exists()), None)
    return parent is not None and parent.is_dir() and os.access(parent, os.W_OK | os.X_OK)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._+-]+", "_", text).strip("_") or "spectrum"


# -- list / show / remove / init-store ----------------------------------------------------------
def cmd_list(args: argparse.Namespace) -> int:
    from rich.table import Table

    from rig.console import console as plain_console

    console = plain_console()
    store = _store(args)
    table = Table(title=f"calibration store {store.root}")
    for col in ("name", "kind", "version", "added", "source / device"):
        table.add_column(col)
    for e in store.entries(all_versions=args.all):
        prov = e.provenance
        what = prov.get("device") or prov.get("instrument") or prov.get("source") or ""
        table.add_row(e.name, e.kind, str(e.version), e.added[:10], str(what))
    console.print(table)
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    import numpy as np

    from calibration.plots import plot_spectrum
    from rig.console import console as plain_console

    console = plain_console()
    store = _store(args)
    entry = store.entry(args.name, args.version)
    if entry.kind == "flat_field":
        _, flat = store.flat_field(entry.name, entry.version)
        console.print(f"{entry.name} v{entry.version} (flat field, {flat.method})", style="bold")
        corner = {f"corner gain {c}": g for c, g in flat.to_dict()["corner_gain"].items()}
        for key, value in {**entry.provenance, **corner}.items():
            console.print(f"  {key}: {value}")
        return 0
    w, v = store.read_native(entry)
    console.print(f"{entry.name} v{entry.version} ({entry.kind}) — {store.root / entry.file}",
                  style="bold")
    console.print(
        f"  added {entry.added}, {w.size} samples {w[0]:g}–{w[-1]:g} nm, "
        f"sha256 {entry.sha256[:12]}…"
    )
    for key, value in entry.provenance.items():
        console.print(f"  {key}: {value}")
    peaks = ", ".join(f"{c} {w[np.argmax(v[:, j])]:g} nm" for j, c in enumerate(entry.columns))
    console.print(f"  peak: {peaks}")
    path = Path(args.plot) if args.plot else Path(f"{_slug(entry.name)}.v{entry.version}.png")
    output_file(path, "--plot")
    plot_spectrum(w, v, entry.columns, f"{entry.name} v{entry.version} ({entry.kind})", path)
    console.print(f"plot written to {path}")
    return 0


def cmd_remove(args: argparse.Namespace) -> int:
    from rig.console import console as plain_console

    console = plain_console()
    store = _store(args)
    versions = [e for e in store.entries() if e.name == args.name]
    if args.version is None and len(versions) > 1 and not args.all:
        raise RigError(
            f"{args.name!r} has {len(versions)} versions",
            "name one with --version N, or pass --all to remove every version",
        )
    for e in store.remove(args.name, args.version):
        console.print(f"removed {e.name} v{e.version} ({e.file})")
    return 0


def cmd_init_store(args: argparse.Namespace) -> int:
    from calibration.store import CalibrationStore
    from rig.console import console as plain_console

    console = plain_console()
    root = output_dir(Path(args.dir), "DIR") if args.dir else _store_root(args)
    store = CalibrationStore.create_default(root)
    console.print(f"wrote default calibration store to {store.root}:")
    for e in store.entries():
        console.print(f"  {e.kind:6} {e.name}")
    console.print(
        "bulb channel SPDs are models: measure your light and `rig calibrate import` it",
        style="yellow",
    )
    return 0


# -- import -------------------------------------------------------------------------------------
def cmd_import(args: argparse.Namespace) -> int:
    from calibration.grid import DEFAULT_GRID
    from calibration.importers import read_spectrum
    from calibration.spectra import resample
    from rig.console import console as plain_console

    console = plain_console()
    store = _store(args, must_exist=False)
    spectrum = read_spectrum(args.file, args.format)
    values = spectrum.column(args.column, args.kind)
    provenance = dict(spectrum.metadata)
    provenance["source"] = provenance.get("source") or f"{spectrum.format} file {spectrum.source}"
    for key in (
        "device",
        "serial",
        "date",
        "instrument",
        "integration_time_ms",
        "operator",
        "notes",
    ):
        given = getattr(args, key)
        if given is not None:
            provenance[key] = given
    if args.kind == "light":
        entry = store.add_light(args.name, spectrum.wavelengths_nm, values, provenance)
    else:
        entry = store.add_camera(args.name, spectrum.wavelengths_nm, values, provenance)
    grid_note = ""
    try:
        resample(spectrum.wavelengths_nm, values, DEFAULT_GRID, source=str(args.file))
    except RigError as error:
        grid_note = f" (warning: {error})"
    console.print(
        f"added {entry.kind} {entry.name!r} version {entry.version} from {spectrum.format} "
        f"({spectrum.wavelengths_nm.size} samples {spectrum.wavelengths_nm[0]:g}–"
        f"{spectrum.wavelengths_nm[-1]:g} nm) to {store.root}{grid_note}"
    )
    return 0


# -- basis --------------------------------------------------------------------------------------
def cmd_basis(args: argparse.Namespace) -> int:
    import numpy as np
    from rich.table import Table

    from calibration.basis import default_basis, pca_basis
    from calibration.grid import DEFAULT_GRID
    from calibration.importers import read_reflectance_set
    from calibration.plots import plot_basis
    from calibration.spectra import resample
    from rig.console import console as plain_console

    console = plain_console()
    output_file(Path(args.plot), "--plot")
    if args.out:
        output_file(Path(args.out), "--out")
    if args.from_file:
        _, w, values = read_reflectance_set(args.from_file)
        refl = resample(w, values.T, DEFAULT_GRID, source=str(args.from_file)).T
        basis = pca_basis(
            refl,
            args.components,
            source=f"{Path(args.from_file).name} ({refl.shape[0]} reflectances)",
        )
    else:
        basis = default_basis(DEFAULT_GRID, args.components)
    table = Table(title=f"uncentred PCA of {basis.source}")
    for col in ("component", "explained", "cumulative"):
        table.add_column(col, justify="right")
    cumulative = np.cumsum(basis.explained_variance)
    for j in range(min(basis.explained_variance.size, max(args.components, 10))):
        style = "bold" if j < args.components else "dim"
        table.add_row(
            str(j + 1),
            f"{100 * basis.explained_variance[j]:.3f} %",
            f"{100 * cumulative[j]:.3f} %",
            style=style,
        )
    console.print(table)
    console.print(
        f"{args.components} components explain {100 * cumulative[args.components - 1]:.3f} % "
        "of the reflectance energy"
    )
    if args.out:
        console.print(f"basis written to {basis.save(args.out)}")
    console.print(f"plot written to {plot_basis(basis, args.plot)}")
    return 0


# -- select -------------------------------------------------------------------------------------
def _candidates(args: argparse.Namespace, store: CalibrationStore | None) -> dict[str, np.ndarray]:
    from calibration import defaults
    from calibration.grid import DEFAULT_GRID
    from calibration.selection import channel_mixtures

    grid = DEFAULT_GRID
    if store is not None:
        channels = {
            n.split("/", 1)[1]: store.light_spd(n, grid)
            for n in store.names("light")
            if n.startswith("bulb/")
        }
    else:
        channels = defaults.rgbcw_channel_spds(grid)
    if args.mixtures:
        if not channels:
            raise RigError("--mixtures needs bulb/<channel> lights in the store", "run init-store")
        return channel_mixtures(channels)
    if args.lights:
        names = [n.strip() for n in args.lights.split(",") if n.strip()]
        if store is None:
            named = {
                k: defaults.illumination_spd(v, channels)
                for k, v in defaults.default_illuminations().items()
            }
            missing = [n for n in names if n not in named]
            if missing:
                raise RigError(
                    f"no calibration store, and {', '.join(missing)} are not built-in "
                    "illuminations",
                    "create a store with `rig calibrate init-store` and import your lights",
                )
            return {n: named[n] for n in names}
        return {n: store.light_spd(n, grid) for n in names}
    if store is not None:
        named_lights = [n for n in store.names("light") if not n.startswith("bulb/")]
        if named_lights:
            return {n: store.light_spd(n, grid) for n in named_lights}
        return {f"bulb/{k}": v for k, v in channels.items()}
    return {
        k: defaults.illumination_spd(v, channels)
        for k, v in defaults.default_illuminations().items()
    }


def cmd_select(args: argparse.Namespace) -> int:
    from rich.table import Table

    from calibration import defaults
    from calibration.basis import SpectralBasis, default_basis
    from calibration.grid import DEFAULT_GRID
    from calibration.importers import read_reflectance_set
    from calibration.plots import plot_selection
    from calibration.selection import rank_illumination_sets
    from calibration.spectra import resample
    from calibration.store import CalibrationStore
    from rig.console import console as plain_console

    console = plain_console()
    output_file(Path(args.plot), "--plot")

    if args.top < 1:
        raise RigError(f"--top {args.top} must be at least 1", "give the number of rows to show")
    root = _store_root(args)
    store = CalibrationStore(root) if (root / "index.yaml").exists() else None
    if store is None:
        console.print(f"no calibration store at {root}: using the built-in models", style="dim")
    if store is not None and args.camera in store.names("camera"):
        camera = store.camera(args.camera, DEFAULT_GRID)
    else:
        camera = defaults.camera_sensitivity(args.camera, DEFAULT_GRID)
    candidates = _candidates(args, store)
    if args.reflectances:
        _, w, values = read_reflectance_set(args.reflectances)
        refl = resample(w, values.T, DEFAULT_GRID, source=str(args.reflectances)).T
        ref_name = str(args.reflectances)
    else:
        refl = defaults.colorchecker_reflectances(DEFAULT_GRID)[1]
        ref_name = "ColorChecker 24"
    basis = SpectralBasis.load(args.basis) if args.basis else default_basis(DEFAULT_GRID)
    if basis.B.shape[0] != DEFAULT_GRID.size:
        raise RigError(f"basis {args.basis} is not on the default grid", "rebuild it")
    scores = rank_illumination_sets(
        candidates,
        camera,
        refl,
        basis,
        max_size=args.max_size,
        noise=args.noise,
        smoothness=args.smoothness,
    )
    table = Table(
        title=f"illumination sets for {args.camera} on {ref_name} "
        f"(noise {args.noise:g} of white, expected RMSE)"
    )
    for col in ("rank", "illuminations", "mean RMSE", "max RMSE", "smoothness"):
        table.add_column(col, justify="right" if col != "illuminations" else "left")
    for rank, s in enumerate(scores[: args.top], start=1):
        table.add_row(
            str(rank),
            " + ".join(s.names),
            f"{s.mean_rmse:.4f}",
            f"{s.max_rmse:.4f}",
            f"{s.smoothness:.2g}",
        )
    console.print(table)
    best_by_size: dict[int, str] = {}
    for s in scores:
        best_by_size.setdefault(len(s.names), f"{' + '.join(s.names)} ({s.mean_rmse:.4f})")
    for k in sorted(best_by_size):
        console.print(f"best with {k}: {best_by_size[k]}")
    path = plot_selection(scores, camera, candidates, DEFAULT_GRID.wavelengths, args.plot, args.top)
    console.print(f"plot written to {path}")
    return 0


# -- camera from a chart -------------------------------------------------------------------------
def cmd_camera(args: argparse.Namespace) -> int:
    return calibrate_camera.run(args, _store(args))


def cmd_flat_field(args: argparse.Namespace) -> int:
    return calibrate_flat_field.run(args, _store(args, must_exist=False))


# -- parser -------------------------------------------------------------------------------------
def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "calibrate",
        help="spectral calibration store, basis and illumination selection",
        description="Manage measured light SPDs and camera sensitivities, build the reflectance "
        "basis and choose the illuminations to capture with.",
    )
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--store",
        metavar="DIR",
        help=f"calibration store (default ${ENV_STORE} or ~/.local/share/spectral-rig/calibration)",
    )
    sub = parser.add_subparsers(dest="calibrate_command", metavar="ACTION", required=True)

    p = sub.add_parser("list", parents=[common], help="list the store's entries")
    p.add_argument("--all", action="store_true", help="show every version, not only the latest")
    p.set_defaults(func=cmd_list)

    p = sub.add_parser("show", parents=[common], help="print an entry's provenance and plot it")
    p.add_argument("name")
    p.add_argument("--version", type=int)
    p.add_argument("--plot", metavar="PNG", help="plot path (default NAME.vN.png)")
    p.set_defaults(func=cmd_show)

    p = sub.add_parser(
        "import",
        parents=[common],
        help="add a measured spectrum (new version if the name exists)",
        description="FILE is a CSV/TSV table, an OceanView export, a SpectraWiz file "
        "(.IRR/.SSM/.ABS/.TRM) or colour:NAME for a colour-science dataset.",
    )
    p.add_argument("file")
    p.add_argument("--kind", choices=("light", "camera"), required=True)
    p.add_argument("--name", required=True, help="entry name, e.g. LED1 or bulb/r")
    p.add_argument("--format", choices=FORMATS, default="auto")
    p.add_argument("--column", help="value column to use when the file has several (lights)")
    p.add_argument("--device", help="measured device (e.g. 'Haodeng WH018 bulb')")
    p.add_argument("--serial")
    p.add_argument("--date", help="measurement date")
    p.add_argument("--instrument", help="spectrometer used")
    p.add_argument("--integration-time-ms", dest="integration_time_ms",
                   type=number(float, above=0, max=3_600_000))
    p.add_argument("--operator")
    p.add_argument("--notes")
    p.set_defaults(func=cmd_import)

    p = sub.add_parser("remove", parents=[common], help="remove an entry (one or all versions)")
    p.add_argument("name")
    p.add_argument("--version", type=int)
    p.add_argument("--all", action="store_true", help="remove every version")
    p.set_defaults(func=cmd_remove)

    p = sub.add_parser("basis", parents=[common], help="build the reflectance basis (PCA)")
    p.add_argument("--from", dest="from_file", metavar="FILE.csv", help="reflectance set")
    p.add_argument("--components", type=number(int, min=1, max=1000), default=8)
    p.add_argument("--out", metavar="NPZ", help="write the basis (.npz)")
    p.add_argument("--plot", metavar="PNG", default="basis.png")
    p.set_defaults(func=cmd_basis)

    p = sub.add_parser("select", parents=[common], help="rank illumination sets (paper Fig. 7)")
    p.add_argument("--camera", default=DEFAULT_CAMERA, help="store entry or built-in")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--lights", help="comma-separated light entries to choose from")
    group.add_argument("--mixtures", action="store_true", help="all on/off mixes of bulb channels")
    p.add_argument("--max-size", type=number(int, min=1, max=16), default=3)
    p.add_argument("--noise", type=number(float, min=0, max=1), default=0.003,
                   help="noise std, fraction of white")
    p.add_argument("--smoothness", type=number(float, min=0, max=1e6),
                   help="fixed smoothness (default: best per set)")
    p.add_argument("--reflectances", metavar="FILE.csv", help="reference set (default CC24)")
    p.add_argument("--basis", metavar="NPZ", help="basis from `rig calibrate basis --out`")
    p.add_argument("--top", type=int, default=15, help="rows to print and plot")
    p.add_argument("--plot", metavar="PNG", default="illumination-selection.png")
    p.set_defaults(func=cmd_select)

    calibrate_camera.add_parser(sub, common, cmd_camera)

    p = sub.add_parser("init-store", parents=[common], help="write the built-in default store")
    p.add_argument("dir", nargs="?", help="directory (default: --store or the default store)")
    p.set_defaults(func=cmd_init_store)

    calibrate_flat_field.add_parser(sub, common, cmd_flat_field)

    p = sub.add_parser("wizard", help="guided measurement of the lights and camera")
    wizard.add_arguments(p)
    p.set_defaults(func=wizard.run)
