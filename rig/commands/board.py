"""`rig board`: print a ChArUco marker board for poses and metric scale.

Writes the sheet (PDF at exact size, or PNG with its DPI) and a profile snippet recording the
board's geometry; after printing, ``--measured-square-mm`` records the printed square size.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from core.errors import RigError
from rig.outpaths import output_file

if TYPE_CHECKING:
    from reconstruct.poses.board import BoardSpec

# The board library's defaults (reconstruct.poses.board.spec, which loads OpenCV), repeated so
# that the parser stays light; a test keeps them equal.
PAPER_SIZES = ("A4", "A3", "A2", "LETTER")  # = tuple(spec.PAPER_SIZES_M)
DEFAULT_DICTIONARY = "DICT_5X5_100"  # = spec.DEFAULT_DICTIONARY
DEFAULT_SQUARES = (10, 7)  # = spec.DEFAULT_SQUARES
DEFAULT_MARKER_RATIO = 0.75  # = spec.DEFAULT_MARKER_RATIO


def _squares(text: str) -> tuple[int, int]:
    try:
        sx, sy = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r} is not COLUMNSxROWS, e.g. 7x5") from exc
    if min(sx, sy) < 2:
        raise argparse.ArgumentTypeError(
            f"{text!r}: a ChArUco board needs at least 2 squares each way, e.g. 7x5"
        )
    return sx, sy


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "board",
        help="generate a printable ChArUco marker board",
        description=(
            "Generate a ChArUco board to lay under the object: it gives every view a metric, "
            "upright pose even when the object has no texture. Writes the sheet and a YAML "
            "profile snippet with its geometry. After printing, measure one square and run "
            "`rig board --snippet SNIPPET --measured-square-mm MM`."
        ),
    )
    parser.add_argument("--out", type=Path, help="sheet to write: .pdf (exact size) or .png")
    parser.add_argument(
        "--size",
        default="A4",
        type=str.upper,
        choices=PAPER_SIZES,
        help="paper size (default A4)",
    )
    parser.add_argument(
        "--squares",
        type=_squares,
        default=DEFAULT_SQUARES,
        metavar="CxR",
        help="chessboard squares, columns x rows (default 10x7)",
    )
    parser.add_argument(
        "--square-mm",
        type=float,
        help="square side in mm (default: the largest whole mm that fits the sheet)",
    )
    parser.add_argument(
        "--marker-ratio",
        type=float,
        default=DEFAULT_MARKER_RATIO,
        help=f"marker side / square side (default {DEFAULT_MARKER_RATIO})",
    )
    parser.add_argument(
        "--dictionary",
        default=DEFAULT_DICTIONARY,
        help=f"ArUco dictionary (default {DEFAULT_DICTIONARY})",
    )
    parser.add_argument("--dpi", type=int, default=300, help="PNG resolution (default 300)")
    parser.add_argument(
        "--snippet",
        type=Path,
        help="profile snippet (YAML) to write, or to update with --measured-square-mm "
        "(default: next to --out, .yaml)",
    )
    parser.add_argument(
        "--measured-square-mm",
        type=float,
        help="side of one square as measured on the print, in mm (records the print's scale)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from reconstruct.poses.board import BoardSpec, write_sheet
    from rig.console import console as plain_console

    console = plain_console(soft_wrap=True)
    measured = None if args.measured_square_mm is None else args.measured_square_mm / 1000
    if args.snippet is not None:
        output_file(args.snippet, "--snippet")
    if args.out is None:
        if args.snippet is None or measured is None:
            raise RigError(
                "nothing to do: no --out sheet and no snippet to update",
                "run `rig board --out board.pdf`, or after printing "
                "`rig board --snippet board.yaml --measured-square-mm MM`",
            )
        spec = BoardSpec.from_yaml(args.snippet).with_measured_square(measured)
        _write_snippet(args.snippet, spec)
        console.print(
            f"{args.snippet}: measured square {measured * 1000:g} mm recorded "
            f"(designed {spec.square_length_m * 1000:g} mm, print scale {spec.scale:.4f})"
        )
        return 0
    output_file(args.out, "--out")
    output_file(args.snippet or args.out.with_suffix(".yaml"), "--snippet")
    spec = BoardSpec.fit_paper(
        paper=args.size,
        squares=args.squares,
        square_length_m=None if args.square_mm is None else args.square_mm / 1000,
        marker_ratio=args.marker_ratio,
        dictionary=args.dictionary,
    )
    sheet = write_sheet(spec, args.out, dpi=args.dpi)
    if measured is not None:
        spec = spec.with_measured_square(measured)
    snippet = args.snippet or args.out.with_suffix(".yaml")
    _write_snippet(snippet, spec)
    sx, sy = spec.squares
    w, h = spec.size_m
    console.print(
        f"{sheet}: {sx}x{sy} ChArUco ({spec.dictionary}) on {spec.paper}, squares "
        f"{spec.square_length_m * 1000:g} mm, markers {spec.marker_length_m * 1000:g} mm, "
        f"board {w * 1000:g} x {h * 1000:g} mm"
        + (f", {args.dpi} dpi" if sheet.suffix.lower() == ".png" else "")
    )
    console.print(f"{snippet}: profile snippet (paste its board: entry into your profile)")
    if measured is None:
        console.print(
            "Print at 100 % (no fit-to-page), measure one square, then run "
            f"`rig board --snippet {snippet} --measured-square-mm MM`."
        )
    return 0


def _write_snippet(path: Path, spec: BoardSpec) -> None:
    from core.files import write_bytes_atomically

    write_bytes_atomically(path, spec.to_yaml().encode())
