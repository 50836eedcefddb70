"""`rig evaluate RECON`: accuracy, completeness, spectral RMSE and light error against truth."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from rig.commands.relight import parse_xyz

if TYPE_CHECKING:
    from rich.table import Table

    from reconstruct.outputs.evaluate import Evaluation


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="compare a reconstruction with ground truth",
        description="Accuracy and completeness (mean distance each way, as in the paper), "
        "spectral RMSE per vertex with an error-map PNG, and the light offset error.",
    )
    parser.add_argument("recon", type=Path, help="SESSION, SESSION/recon or a reflectance.npz")
    parser.add_argument("--gt-mesh", type=Path, required=True, help="true mesh (PLY/OBJ)")
    parser.add_argument(
        "--gt-reflectance", type=Path, required=True, help=".npy (N_gt, N_λ) per true vertex"
    )
    parser.add_argument("--gt-light-offset", default=None, help="true plate offset x,y,z (m)")
    parser.set_defaults(func=handle)


def table(ev: Evaluation, title: str = "evaluation") -> Table:
    from rich.table import Table

    out = Table(title=title, show_header=False)
    for key, value in ev.table():
        out.add_row(key, value)
    return out


def handle(args: argparse.Namespace) -> int:
    from rich.console import Console

    from core.session import RECON_DIR
    from reconstruct.outputs import export
    from reconstruct.outputs.evaluate import evaluate

    recon = Path(args.recon)
    if recon.is_dir() and not (recon / export.REFLECTANCE_FILE).is_file():
        recon = recon / RECON_DIR
    offset = (
        None
        if args.gt_light_offset is None
        else parse_xyz(args.gt_light_offset, "--gt-light-offset")
    )
    ev = evaluate(recon, args.gt_mesh, args.gt_reflectance, offset)
    console = Console()
    console.print(table(ev))
    for f in ev.files:
        console.print(f"  {f}", highlight=False)
    return 0
