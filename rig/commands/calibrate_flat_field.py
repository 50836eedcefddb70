"""`rig calibrate flat-field`: the lens's fall-off towards the corners, fitted to white card
frames or taken from lensfun's profile of a known camera and lens, stored as a flat-field entry
that decode divides the frames by (calibration.flat_field).

The libraries are imported inside the handler so that building the `rig` parser stays fast.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from core.errors import RigError
from rig.cliargs import number

if TYPE_CHECKING:
    from calibration.store import CalibrationStore


def run(args: argparse.Namespace, store: CalibrationStore) -> int:
    from rig.console import console as plain_console

    console = plain_console()
    if args.lensfun:
        flat, provenance, name = _lensfun_flat_field(args)
    else:
        flat, provenance, name = _card_flat_field(args)
    entry = store.add_flat_field(name, flat, provenance)
    corner = ", ".join(f"{g:.3f}" for g in flat.corner_gain())
    console.print(
        f"added flat field {entry.name!r} version {entry.version} ({flat.method}, corner gain "
        f"R, G, B {corner}) to {store.root}; name it in the profile as "
        f"calibration.flat_field: {entry.name}",
        highlight=False,
    )
    return 0


def _card_flat_field(args: argparse.Namespace) -> tuple[Any, dict[str, Any], str]:
    from rig.wizard.common import today
    from rig.wizard.flat_field import CardGeometry, fit_card_frames

    if not args.raws or not args.camera:
        raise RigError(
            "rig calibrate flat-field needs white card RAW files and --camera NAME "
            "(or --lensfun ...)",
            "e.g. `rig calibrate flat-field card1.CR2 card2.CR2 --camera 5D2 "
            "--card-distance-m 0.4 --focal-px 6000`",
        )
    geometry = None
    if not args.diffuser:
        if args.card_distance_m is None or args.focal_px is None:
            raise RigError(
                "a white card flat field needs --card-distance-m and --focal-px",
                "give them (the light's own fall-off on the card is divided out), or "
                "--diffuser for an opal diffuser over the lens",
            )
        geometry = CardGeometry(args.card_distance_m, _offset(args.light_offset_m), args.focal_px)
    for path in [*args.raws, *args.dark]:
        if not Path(path).is_file():
            raise RigError(f"white card frame {path} does not exist", "give RAW files")
    flat = fit_card_frames(
        [Path(p) for p in args.raws], [Path(p) for p in args.dark], geometry, {}
    )
    provenance = {
        "source": f"white card, {len(args.raws)} frames ({', '.join(map(str, args.raws))})",
        "device": args.camera,
        "date": today(),
        "notes": flat.details.get("geometry"),
    }
    return flat, provenance, args.name or f"flat/{args.camera}"


def _offset(text: str) -> tuple[float, float, float]:
    try:
        x, y, z = (float(v) for v in text.split(","))
    except ValueError as exc:
        raise RigError(
            f"--light-offset-m {text!r}", "write X,Y,Z in metres (camera frame)"
        ) from exc
    return x, y, z


def _lensfun_flat_field(args: argparse.Namespace) -> tuple[Any, dict[str, Any], str]:
    from calibration.lensfun import lensfun_flat_field
    from rig.wizard.common import today

    if args.raws or args.lens is None or args.focal is None or args.aperture is None:
        raise RigError(
            "--lensfun needs --lens, --focal and --aperture, and no RAW files",
            'e.g. `rig calibrate flat-field --lensfun "Canon Canon EOS 5D Mark II" '
            '--lens "Canon EF 50mm f/1.4 USM" --focal 50 --aperture 2.8 --size 5616x3744`',
        )
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError as exc:
        raise RigError(f"--size {args.size!r}", "write WIDTHxHEIGHT in pixels") from exc
    flat = lensfun_flat_field(args.lensfun, args.lens, args.focal, args.aperture, (width, height))
    provenance = {
        "source": f"lensfun profile: {flat.details['lensfun_lens']} on "
        f"{flat.details['lensfun_camera']}, {args.focal:g} mm f/{args.aperture:g}",
        "device": args.lensfun,
        "date": today(),
    }
    name = args.name or f"flat/{args.lens} {args.focal:g}mm f{args.aperture:g}"
    return flat, provenance, name


def add_parser(
    sub: argparse._SubParsersAction,
    common: argparse.ArgumentParser,
    handler: Callable[[argparse.Namespace], int],
) -> None:
    """The `flat-field` action of `rig calibrate`, run by ``handler``."""
    p = sub.add_parser(
        "flat-field",
        parents=[common],
        help="the lens's fall-off, from white card frames or a lensfun profile",
        description="Fit the lens's fall-off towards the corners to RAW frames of a diffuse "
        "white card filling the frame under the rig's light (several positions), or take it "
        "from lensfun's profile of a known camera and lens; store it as a flat-field entry, "
        "which decode divides the frames by when the profile names it "
        "(calibration.flat_field).",
    )
    p.add_argument("raws", nargs="*", metavar="RAW", help="white card frames")
    p.add_argument("--camera", help="the camera the frames come from (recorded, and the name)")
    p.add_argument("--name", help="entry name (default flat/CAMERA, or flat/LENS ...)")
    p.add_argument("--dark", action="append", default=[], metavar="RAW",
                   help="a frame with the light off, subtracted (repeatable)")
    p.add_argument("--card-distance-m", type=number(float, above=0, max=100),
                   help="camera to card along the axis, m")
    p.add_argument("--focal-px", type=number(float, above=0, max=1e6),
                   help="the camera's focal length in pixels")
    p.add_argument("--light-offset-m", default="0,0,0", metavar="X,Y,Z",
                   help="the light in the camera frame, m (default 0,0,0)")
    p.add_argument("--diffuser", action="store_true",
                   help="an opal diffuser over the lens (evenly lit: no card geometry)")
    p.add_argument("--lensfun", metavar='"MAKER MODEL"', help="camera in lensfun's database")
    p.add_argument("--lens", help="lens model in lensfun's database")
    p.add_argument("--focal", type=number(float, above=0, max=10_000), metavar="MM",
                   help="focal length, mm")
    p.add_argument("--aperture", type=number(float, min=0.5, max=256), metavar="F",
                   help="f-number")
    p.add_argument("--size", default="6000x4000", metavar="WxH",
                   help="the camera's image size (default 6000x4000: its aspect ratio matters)")
    p.set_defaults(func=handler)
