"""`rig export PATH --glb FILE.glb`: a reconstruction as glTF 2.0 for Blender, three.js or a
web viewer (linear vertex colours under one illuminant, the spectra as custom attributes)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "export",
        help="write a reconstruction as a glTF binary (.glb)",
        description="Write the mesh of PATH (a session, its recon/ folder or `rig demo`'s "
        "folder) as glTF 2.0: COLOR_0 holds the linear sRGB of each vertex's reflectance "
        "under --illuminant, _REFLECTANCE_400 ... _REFLECTANCE_700 the reflectance itself.",
    )
    p.add_argument("path", type=Path, help="a session, its recon/ folder or the demo's folder")
    p.add_argument("--glb", type=Path, required=True, metavar="FILE.glb", help="file to write")
    p.add_argument("--illuminant", default="D65", metavar="NAME|FILE",
                   help="a CIE illuminant (D65, A, FL11, LED-B3, ...) or an SPD file for the "
                   "vertex colours (default D65)")
    p.set_defaults(func=handle)


def handle(args: argparse.Namespace) -> int:
    from calibration.grid import SpectralGrid
    from core.errors import RigError
    from reconstruct.outputs.gltf import write_glb
    from reconstruct.outputs.relight import illuminant_spd
    from reconstruct.outputs.result import load_result
    from rig.console import console as plain_console

    glb = Path(args.glb)
    if glb.is_dir() or glb.suffix.lower() != ".glb":
        raise RigError(f"--glb {glb} is not a .glb file name", "give a file name ending in .glb")
    result = load_result(args.path)
    spd = illuminant_spd(args.illuminant, SpectralGrid.from_wavelengths(result.wavelengths_nm))
    glb.parent.mkdir(parents=True, exist_ok=True)
    write_glb(glb, result, spd, args.illuminant)
    plain_console(stderr=True).print(
        f"wrote {glb} ({glb.stat().st_size / 1e6:.1f} MB, {len(result.mesh.vertices)} vertices, "
        f"colours under {args.illuminant})", highlight=False
    )
    return 0
