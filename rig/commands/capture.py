"""`rig capture`: guided capture session (resumable; see rig.capture)."""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

from core import interrupts
from core.errors import RigError
from core.text import printable
from profiles import shipped_profiles
from rig.cliargs import SEED_MAX, number
from rig.outpaths import output_dir


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "capture",
        help="guided capture session",
        description="Capture every view under every illumination into a session directory. "
        "Ctrl-C stops after the frame in flight; --resume continues exactly there.",
    )
    parser.add_argument(
        "--profile",
        default=None,
        help=f"shipped profile ({', '.join(shipped_profiles())}) or a YAML file "
        "(default: sim for a new session)",
    )
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", type=Path, help="new session directory")
    where.add_argument(
        "--resume", type=Path, metavar="SESSION", help="continue an interrupted session"
    )
    parser.add_argument(
        "--yes", "-y", action="store_true", help="no prompts (simulated rigs, automation)"
    )
    parser.add_argument("--note", default="", help="free text for session.yaml (object, operator)")
    parser.add_argument("--seed", type=number(int, min=0, max=SEED_MAX), default=None,
                        help="simulated scene seed (default 0)")
    parser.add_argument(
        "--reconstruct",
        action="store_true",
        help="run `rig reconstruct` on the session when the capture ends",
    )
    parser.add_argument(
        "--trust-session-devices",
        action="store_true",
        help="on --resume, open devices whose session snapshot runs a program "
        "(subprocess transport) without asking",
    )
    parser.set_defaults(func=handle, stop_hint=stop_hint)


def stop_hint(args: argparse.Namespace) -> str:
    from core.session import SESSION_FILE

    session = args.resume if args.resume is not None else args.out
    if (session / SESSION_FILE).is_file():
        return f"every completed frame is saved; resume with `rig capture --resume {session}`"
    profile = args.profile or "sim"
    return (
        f"no frame was captured; `rig capture --resume {session} --profile {profile}` "
        "starts it afresh"
    )


def handle(args: argparse.Namespace) -> int:
    from rig.capture import CaptureStopped, run_capture
    from rig.console import console as plain_console

    console = plain_console(stderr=True)
    session = args.resume if args.resume is not None else args.out
    output_dir(session, "--resume" if args.resume is not None else "--out")
    profile = args.profile if args.profile is not None or args.resume else "sim"
    try:
        out = run_capture(
            profile,
            session,
            yes=args.yes,
            resume=args.resume is not None,
            seed=args.seed,
            console=console,
            notes=args.note,
            trust_devices=args.trust_session_devices,
        )
    except CaptureStopped as stopped:
        if interrupts.received() is None:  # 'q' or Ctrl-C at a prompt; a signal gets its line
            console.print(str(stopped), style="yellow")
        return 130
    print(printable(out))
    if args.reconstruct:
        return reconstruct(out)
    return 0


def reconstruct(session: Path) -> int:
    """Run the reconstruction pipeline on a finished session."""
    from rig.warmup import compile_kernels_once

    try:
        pipeline = importlib.import_module("reconstruct.run.pipeline")
    except ImportError as exc:
        raise RigError(
            "the reconstruction pipeline (reconstruct.run.pipeline) is not available",
            f"the frames are safe; run `rig reconstruct {session}` once it is installed",
        ) from exc
    compile_kernels_once()
    pipeline.run_reconstruction(session)
    print(printable(session / "recon"))
    return 0
