"""`rig evaluate RECON`: accuracy, completeness, spectral RMSE, CIEDE2000 and light error
against truth."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from rig.commands.relight import parse_xyz

if TYPE_CHECKING:
    from rich.table import Table

    from calibration.colour_difference import Illuminant
    from reconstruct.outputs.evaluate import Evaluation


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="compare a reconstruction with ground truth",
        description="Accuracy and completeness (mean distance each way, as in the paper), "
        "spectral RMSE per vertex with an error-map PNG, CIEDE2000 (CIE 1931 2° observer) "
        "under D65, A and any --illuminant per vertex and per patch (when patch.npy lies "
        "beside the true reflectance), and the light offset error.",
    )
    parser.add_argument("recon", type=Path, help="SESSION, SESSION/recon or a reflectance.npz")
    parser.add_argument("--gt-mesh", type=Path, required=True, help="true mesh (PLY/OBJ)")
    parser.add_argument(
        "--gt-reflectance", type=Path, required=True,
        help=".npy (N_gt, N_λ) per true vertex; a patch.npy beside it (patch label per true "
        "vertex, -1 = none) adds the per-patch ΔE00",
    )  # fmt: skip
    parser.add_argument("--gt-light-offset", default=None, help="true plate offset x,y,z (m)")
    parser.add_argument(
        "--illuminant", action="append", default=[], metavar="NAME_OR_CSV",
        help="also report ΔE00 under this illuminant (repeatable): a CIE name (FL2, LED-B3, "
        "D50 …), an SPD file (CSV wavelength_nm,power) or a light entry of the session's "
        "calibration snapshot or the calibration store; D65 and A are always reported",
    )  # fmt: skip
    parser.set_defaults(func=handle)


def table(ev: Evaluation, title: str = "evaluation") -> Table:
    from rich.table import Table

    out = Table(title=title, show_header=False)
    for key, value in ev.table():
        out.add_row(key, value)
    return out


def patches(ev: Evaluation) -> Table | None:
    """The per-patch ΔE00 table (None when the truth has no patches)."""
    from rich.table import Table

    from reconstruct.outputs.evaluate import patch_table

    columns, rows = patch_table(ev.colour)
    if not rows:
        return None
    out = Table(title="per patch: ΔE00 and spectral RMSE of the patch's median spectrum")
    for c in columns:
        out.add_column(c, justify="left" if c == "patch" else "right")
    for row in rows:
        out.add_row(*row)
    return out


def lights(names: list[str], recon: Path) -> list[Illuminant]:
    """D65, A and the user's illuminants; store entries from the session's snapshot first."""
    from calibration.colour_difference import DEFAULT_ILLUMINANTS, illuminant
    from calibration.store import CalibrationStore, default_store_path

    session_cal = recon.parent / "calibration"  # recon is SESSION/recon
    store = CalibrationStore(session_cal if session_cal.is_dir() else default_store_path())
    wanted = [*DEFAULT_ILLUMINANTS, *(n for n in names if n not in DEFAULT_ILLUMINANTS)]
    return [illuminant(n, store=store) for n in wanted]


def handle(args: argparse.Namespace) -> int:
    from core.session import RECON_DIR
    from reconstruct.outputs import export
    from reconstruct.outputs.evaluate import evaluate
    from rig.console import console as plain_console

    recon = Path(args.recon)
    if recon.is_dir() and not (recon / export.REFLECTANCE_FILE).is_file():
        recon = recon / RECON_DIR
    offset = (
        None
        if args.gt_light_offset is None
        else parse_xyz(args.gt_light_offset, "--gt-light-offset")
    )
    recon_dir = recon if recon.is_dir() else recon.parent
    ev = evaluate(
        recon, args.gt_mesh, args.gt_reflectance, offset,
        illuminants=lights(args.illuminant, recon_dir),
    )  # fmt: skip
    console = plain_console()
    console.print(table(ev))
    per_patch = patches(ev)
    if per_patch is not None:
        console.print(per_patch)
    for f in ev.files:
        console.print(f"  {f}", highlight=False)
    return 0
