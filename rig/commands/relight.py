"""`rig relight SESSION`: render the reconstruction from a captured view or a new camera under
a point light of any illuminant, with cast shadows, as an sRGB PNG."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from core.errors import RigError
from core.text import printable
from rig.cliargs import MAX_VIEWS, number
from rig.outpaths import output_file

if TYPE_CHECKING:
    import numpy as np


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "relight",
        help="render the reconstruction under a new light (PNG)",
        description="Render SESSION/recon (mesh + spectral reflectance) from a captured view or "
        "a camera file, lit by a point light with a CIE illuminant or a measured SPD.",
    )
    parser.add_argument(
        "session", type=Path, help="session directory with recon/ (or `rig demo`'s folder)"
    )
    which = parser.add_mutually_exclusive_group(required=True)
    which.add_argument("--view", type=number(int, min=0, max=MAX_VIEWS - 1),
                       help="render from captured view N (from 0)")
    which.add_argument(
        "--camera",
        type=Path,
        help="YAML (width, height, focal_px, eye, target) or a COLMAP text model folder",
    )
    parser.add_argument(
        "--light-pos",
        default=None,
        help="x,y,z in metres (world); default: the estimated light of the view, or the "
        "estimated plate offset from --camera",
    )
    parser.add_argument(
        "--illuminant", default="D65", help="CIE name (D65, A, F2, …) or a CSV wavelength_nm,power"
    )
    parser.add_argument("--exposure", type=number(float, above=0, max=1000), default=0.8,
                        help="white at the scene reads this")
    parser.add_argument(
        "--out", type=Path, default=None, help="PNG path (default in recon/relight/)"
    )
    parser.set_defaults(func=handle)


MAX_COORDINATE_M = 1000.0  # a light farther than a kilometre lights a scene of centimetres as 0


def parse_xyz(text: str, what: str) -> np.ndarray:
    import numpy as np

    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError as error:
        raise RigError(
            f"{what} {text!r} is not x,y,z", "give three numbers, e.g. 0.1,0,0.3"
        ) from error
    if v.shape != (3,):
        raise RigError(f"{what} {text!r} has {v.size} numbers", "give three numbers: x,y,z")
    if not np.all(np.isfinite(v)):
        raise RigError(f"{what} {text!r} is not finite", "give three finite numbers in metres")
    if np.any(np.abs(v) > MAX_COORDINATE_M):
        raise RigError(f"{what} {text!r} is too far", f"allowed: each coordinate in "
                       f"[-{MAX_COORDINATE_M:g}, {MAX_COORDINATE_M:g}] m")
    return v


def handle(args: argparse.Namespace) -> int:
    # Every argument is checked before the reconstruction is read.
    import numpy as np

    from core.session import RECON_DIR
    from reconstruct.outputs import export
    from reconstruct.outputs.relight import (
        Camera,
        encode_srgb,
        load_camera_file,
        relight,
        write_png,
    )
    from reconstruct.poses.output import load as load_poses

    if args.out is not None:
        output_file(args.out, "--out")
    position = None if args.light_pos is None else parse_xyz(args.light_pos, "--light-pos")
    file_camera = None if args.camera is None else load_camera_file(args.camera)
    from core.session import find_session

    recon = find_session(Path(args.session)) / RECON_DIR
    data = export.read_reflectance_npz(recon / export.REFLECTANCE_FILE)
    report_path = recon / export.REPORT_FILE
    if not report_path.is_file():
        raise RigError(f"{report_path} is missing", f"run `rig reconstruct {args.session}` first")
    report = json.loads(report_path.read_text())
    light = report["light"]
    if file_camera is None:
        intr, poses, _ = load_poses(recon / "poses")
        views = sorted(poses)
        if args.view not in poses:
            raise RigError(
                f"view {args.view} has no pose in {recon / 'poses'}",
                f"choose one of {', '.join(map(str, views))}",
            )
        camera = Camera(intr[args.view], poses[args.view])
        default_light = np.asarray(light["positions_m"][views.index(args.view)])
        name = f"view{args.view:03d}"
    else:
        camera = file_camera
        if light.get("offset_m") is not None:
            default_light = camera.pose.light_position(np.asarray(light["offset_m"]))
        else:
            default_light = camera.pose.center
        name = args.camera.stem
    position = default_light if position is None else position
    image = relight(
        np.asarray(data["vertices"], float),
        np.asarray(data["faces"]),
        np.asarray(data["reflectance"], float),
        np.asarray(data["wavelengths_nm"], float),
        camera,
        position,
        args.illuminant,
        exposure=args.exposure,
    )
    illum = (
        Path(args.illuminant).stem if args.illuminant.lower().endswith(".csv") else args.illuminant
    )
    out = args.out or recon / "relight" / f"{name}_{illum}.png"
    write_png(Path(out), encode_srgb(image))
    print(printable(out))
    return 0
