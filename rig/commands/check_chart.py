"""`rig check-chart SESSION`: find a colour chart in the session's frames, estimate its
patches' reflectances through the session's decode and calibration, and compare them with
the chart's reference (ΔE00 under D65 and A, spectral RMSE, a plot)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from rig.cliargs import MAX_VIEWS, number
from rig.outpaths import output_dir

if TYPE_CHECKING:
    from rich.table import Table

    from reconstruct.chart.check import ChartCheck

LAYOUTS = ("classic24",)  # reconstruct.chart.detect.LAYOUTS, repeated so --help loads no cv2
OUT_DIR = "chart_check"  # under SESSION/recon/


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "check-chart",
        help="check the colour against a chart in the frames (ΔE00 per patch)",
        description="Find a colour chart (ColorChecker Classic 24) in the session's frames, "
        "estimate each patch's reflectance through the session's own decode and calibration "
        "snapshot (the chart's shading fitted as a plane over the chart), and compare with "
        "the reference reflectances: ΔE00 (CIE 1931 2°) under D65, A and any --illuminant, "
        "spectral RMSE, and a plot. Writes chart_check.{json,csv,png} into "
        f"SESSION/recon/{OUT_DIR}/ (or --out).",
    )
    parser.add_argument("session", type=Path, help="session directory")
    parser.add_argument(
        "--view", type=number(int, min=0, max=MAX_VIEWS - 1), action="append", default=None,
        metavar="N",
        help="look only in view N (repeatable); default every view",
    )  # fmt: skip
    parser.add_argument(
        "--reference", type=Path, default=None,
        help="CSV wavelength_nm,<patch 1>,…,<patch N> of the chart's reflectances (0–1), "
        "patches row by row from the top-left; default the ColorChecker 24 (BabelColor)",
    )  # fmt: skip
    parser.add_argument("--layout", choices=LAYOUTS, default=LAYOUTS[0], help="chart layout")
    parser.add_argument(
        "--config", type=Path, default=None,
        help="the reconstruct config YAML (its decode section decodes the frames)",
    )  # fmt: skip
    parser.add_argument(
        "--illuminant", action="append", default=[], metavar="NAME_OR_CSV",
        help="also report ΔE00 under this illuminant (repeatable): a CIE name, an SPD CSV "
        "or a light entry of the session's calibration snapshot",
    )  # fmt: skip
    parser.add_argument(
        "--out", type=Path, default=None, help=f"output folder (default SESSION/recon/{OUT_DIR})"
    )
    parser.set_defaults(func=handle)


def table(check: ChartCheck) -> Table:
    from rich.table import Table

    from reconstruct.chart.report import rows

    lines = rows(check)
    out = Table(title=f"chart check against {check.reference.source}")
    for key in lines[0]:
        out.add_column(key, justify="left" if key == "name" else "right")
    for line in lines:
        out.add_row(*(f"{v:.2f}" if isinstance(v, float) and k != "rmse" else str(v)
                      for k, v in line.items()))  # fmt: skip
    return out


def handle(args: argparse.Namespace) -> int:
    from calibration.colour_difference import DEFAULT_ILLUMINANTS, illuminant
    from calibration.store import CalibrationStore
    from core.lock import locked
    from core.session import Session
    from reconstruct.chart.check import CHECK_CHART, check_session
    from reconstruct.chart.detect import layout
    from reconstruct.chart.reference import default_reference, read_reference
    from reconstruct.chart.report import write
    from reconstruct.run.pipeline import load_config
    from rig.console import console as plain_console

    session = Session.open(args.session)
    out = output_dir(args.out or session.recon_dir / OUT_DIR, "--out")
    chart = layout(args.layout)
    if args.reference is None:
        reference = default_reference(chart)
    else:
        reference = read_reference(args.reference, chart)
    decode_config = load_config(args.config).get("decode")
    wanted = [*DEFAULT_ILLUMINANTS, *(n for n in args.illuminant if n not in DEFAULT_ILLUMINANTS)]
    store = CalibrationStore(session.calibration_dir) if session.calibration_dir.is_dir() else None
    lights = [illuminant(n, store=store) for n in wanted]
    with locked(session.root, CHECK_CHART):  # decode and outputs as one writer
        check = check_session(
            session, reference, chart_layout=chart.name, views=args.view,
            decode_config=decode_config, illuminants=lights,
        )  # fmt: skip
        files = write(check, chart, out)
    console = plain_console()
    console.print(table(check))
    summary = check.summary()
    means = ", ".join(
        f"{n} {summary[f'delta_e00_{n}_mean']:.2f} (max {summary[f'delta_e00_{n}_max']:.2f})"
        for n in check.delta_e
    )
    console.print(
        f"ΔE00 mean {means}; spectral RMSE mean {summary['rmse_mean']:.4f}; "
        f"views {', '.join(str(v.view) for v in check.views)}",
        highlight=False,
    )
    for f in files:
        console.print(f"  {f}", highlight=False)
    return 0
