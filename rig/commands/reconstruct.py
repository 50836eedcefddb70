"""`rig reconstruct SESSION`: decode → poses → initial mesh → visibility → subdivide →
joint optimisation → export, outputs in SESSION/recon/."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from core.errors import RigError
from core.text import printable
from rig.cliargs import number

# reconstruct.stages.resolution.MAX_SIDE's presets (kept equal by tests/rig/test_startup.py)
DETAILS = ("draft", "standard", "fine")

if TYPE_CHECKING:
    from rich.console import Console

    from reconstruct.run.pipeline import Reconstruction


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "reconstruct",
        help="mesh + spectral reflectance per vertex + light position from a session",
        description="Run both halves of the pipeline on a captured session: decode, poses, "
        "initial mesh, visibility, √3 subdivision, then the joint optimisation of shape, "
        "spectral reflectance and light position. Stages resume where they stopped. "
        "Outputs: SESSION/recon/mesh.ply, reflectance.npz, report.json and PNG plots.",
    )
    parser.add_argument("session", type=Path, help="session directory (from `rig capture`)")
    parser.add_argument(
        "--initial-mesh", type=Path, default=None, help="use this mesh instead of MVS (PLY/OBJ)"
    )
    parser.add_argument(
        "--config",
        type=Path,
        default=None,
        help="YAML with sections decode, poses, mesh, procam, visibility, subdivide, optimise",
    )
    parser.add_argument(
        "--detail",
        choices=DETAILS,
        default=None,
        help="working resolution: the decoded frames' long side at most 1000 (draft), 2000 "
        "(standard, the default) or 4000 px (fine); each stage then works at the pyramid level "
        "its target edge needs (config section `resolution`)",
    )
    parser.add_argument(
        "--edge-mm",
        type=number(float, above=0.0, max=1e4),
        default=None,
        help="the mesh's target edge in millimetres (metric poses only; default: 2 px of the "
        "decoded frames); PatchMatch and the optimiser work at the levels it needs",
    )
    parser.add_argument(
        "--keep-intermediates",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="keep the decoded frames in SESSION/recon/decoded after a successful export "
        "(by default they are deleted: the bulk of recon/; a later run decodes them again)",
    )
    parser.add_argument(
        "--status",
        action="store_true",
        help="print the state of the last run on SESSION (running, complete, failed, "
        "interrupted) and exit",
    )
    parser.set_defaults(func=handle, stop_hint=stop_hint)


def with_resolution(
    config: dict[str, Any], detail: str | None, edge_mm: float | None
) -> dict[str, Any]:
    """The config with ``--detail`` / ``--edge-mm`` in its ``resolution`` section (the flags
    win over the file)."""
    flags = {k: v for k, v in (("detail", detail), ("edge_mm", edge_mm)) if v is not None}
    if not flags:
        return config
    return {**config, "resolution": {**(config.get("resolution") or {}), **flags}}


def stop_hint(args: argparse.Namespace) -> str:
    return f"run `rig reconstruct {args.session}` again (same options) to resume where it stopped"


def summary(console: Console, rec: Reconstruction) -> None:
    from rich.table import Table

    light = rec.report["light"]
    table = Table(title="reconstruction", show_header=False)
    table.add_row(
        "vertices / observed", f"{rec.report['vertices']} / {rec.report['observed_vertices']}"
    )
    if light["offset_m"] is not None:
        table.add_row(
            "light offset (camera frame)",
            ", ".join(f"{v * 100:.2f}" for v in light["offset_m"]) + " cm",
        )
    table.add_row(
        "reflectance scale", "absolute" if rec.report["reflectance_scale_absolute"] else "relative"
    )
    table.add_row("time", f"{sum(rec.report['timings_s'].values()):.1f} s")
    table.add_row("resolution", resolution_line(rec.report["resolution"]))
    disk = rec.report["intermediates_mb"]
    deleted = disk["decoded_frames_deleted"]
    stages = ", ".join(f"{k} {v:.0f}" for k, v in disk["stages"].items() if v >= 0.5)
    table.add_row(
        "intermediates",
        f"{disk['total']:.0f} MB ({stages})"
        + (f"; {deleted:.0f} MB of decoded frames deleted, {disk['left']:.0f} MB left"
           if deleted else ""),
    )
    for path in (rec.mesh_path, rec.reflectance_path, rec.report_path, *rec.plots):
        table.add_row(path.name, str(path))
    console.print(table)


def resolution_line(res: dict[str, Any]) -> str:
    """``standard: levels decode 2 (1404×936), PatchMatch 3 (702×468), optimiser 2 (…); edge
    2 px = 0.37 mm`` (level 0: the RAW frame's size)."""
    levels = ", ".join(
        f"{name} {res['levels'][key]} ({res['sizes'][key][0]}×{res['sizes'][key][1]})"
        for key, name in (("decode", "decode"), ("patchmatch", "PatchMatch"),
                          ("optimise", "optimiser"))
    )
    edge = f"{res['edge_px']:.3g} px"
    if res["edge_mm"] is not None:
        edge += f" = {res['edge_mm']:.3g} mm"
    return f"{res['detail']}: levels {levels}; edge {edge}"


# Exit status of a reconstruction that finished without some unusable frames (corrupt or
# changed RAW files, skipped by decode.on_bad_frame: skip): the outputs are written, but the
# caller (a script, a batch of sessions) must not take the run as clean.
EXIT_SKIPPED_FRAMES = 3


def handle(args: argparse.Namespace) -> int:
    from core.session import RECON_DIR, Session

    if args.status:
        from reconstruct.run.status import describe, read_status

        print(printable(describe(read_status(Path(args.session) / RECON_DIR))))
        return 0
    if args.initial_mesh is not None and not args.initial_mesh.is_file():
        raise RigError(
            f"--initial-mesh {args.initial_mesh} is not a file", "give a PLY, OBJ, STL, OFF or GLB"
        )
    # the pipeline (pycolmap, numba, OpenCV) is imported for a run only
    from rich.text import Text

    from reconstruct.frames.decode import list_unusable
    from reconstruct.run.logfile import run_logged
    from reconstruct.run.pipeline import load_config
    from rig.console import console as plain_console
    from rig.warmup import compile_kernels_once

    console = plain_console(stderr=True)
    config = with_resolution(load_config(args.config), args.detail, args.edge_mm)
    session = Session.open(args.session)  # a wrong path fails now, not after the warm-up
    compile_kernels_once(console)
    rec = run_logged(session, config, args.initial_mesh, args.verbose, console,
                     keep_intermediates=args.keep_intermediates)
    summary(console, rec)
    print(printable(rec.recon_dir))
    skipped = rec.report["skipped_frames"]
    if skipped:
        console.print(
            Text.assemble(
                ("warning:", "bold yellow"),
                f" {len(skipped)} frame(s) were unusable and left out "
                f"({list_unusable(skipped)}) — recapture "
                "or restore them and run again, or set decode.on_bad_frame: stop to refuse",
            ),
            soft_wrap=True,
        )
        return EXIT_SKIPPED_FRAMES
    return 0
