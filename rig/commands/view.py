"""`rig view SESSION|RECON`: the reconstruction in the browser, or `--export FILE.html`."""

from __future__ import annotations

import argparse
from pathlib import Path

from core.errors import RigError

# rig.view.colour's (it loads colour-science), repeated so that the parser stays light; a test
# keeps them equal.
DEFAULT_ILLUMINANTS = ("D65", "A", "FL2", "FL11", "LED-B3", "LED-V1")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "view",
        help="interactive 3-D view of a reconstruction's per-vertex spectra in the browser",
        description="Serve (on 127.0.0.1 only) or export one self-contained HTML page: the mesh "
        "in sRGB under a chosen illuminant, a click plots a vertex's spectrum.",
    )
    p.add_argument("path", type=Path,
                   help="a session folder, its recon/ folder or `rig demo`'s folder")
    p.add_argument("--export", type=Path, metavar="FILE.html",
                   help="write one self-contained page (works offline) instead of serving")
    p.add_argument("--illuminant", action="append", metavar="NAME|FILE",
                   help="a CIE illuminant (D65, A, FL11, LED-B3, ...) or an SPD file; repeat "
                   f"for several (default: {', '.join(DEFAULT_ILLUMINANTS)})")
    p.add_argument("--port", type=int, default=0, help="port on 127.0.0.1 (default: a free one)")
    p.add_argument("--no-browser", action="store_true", help="do not open a browser")
    p.set_defaults(func=handle)


def handle(args: argparse.Namespace) -> int:
    from calibration.grid import SpectralGrid
    from rig.console import console as plain_console
    from rig.view.colour import illuminant_matrices
    from rig.view.data import load_view_data
    from rig.view.page import build_page, export_page
    from rig.view.serve import serve

    console = plain_console(stderr=True)
    if args.export is not None and args.export.is_dir():
        raise RigError(f"--export {args.export} is a folder", "give a file name ending in .html")
    if not 0 <= args.port <= 65535:
        raise RigError(f"--port {args.port} is not a port number", "give 0..65535 (0: any free)")
    data = load_view_data(args.path)
    grid = SpectralGrid.from_wavelengths(data.wavelengths_nm)
    page = build_page(data, illuminant_matrices(args.illuminant or list(DEFAULT_ILLUMINANTS), grid))
    if args.export is not None:
        export_page(args.export, page)
        console.print(f"wrote {args.export} ({len(page) / 1e6:.1f} MB, works offline)")
        return 0
    serve(page, args.port, not args.no_browser,
          lambda url: console.print(f"viewer at {url} (Ctrl-C to stop)"))
    return 0
