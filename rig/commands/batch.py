"""`rig batch SESSIONS... | --list FILE`: reconstruct a collection on a Dask cluster."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from core.errors import MissingDependencyError, RigError
from rig.commands.reconstruct import EXIT_SKIPPED_FRAMES
from rig.outpaths import output_file

if TYPE_CHECKING:
    from rig.batch.task import Outcome

MAX_WORKERS = 1024  # more processes than any one machine's cores and memory take


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "batch",
        help="reconstruct many sessions on a Dask cluster (local or existing)",
        description="Reconstruct every session as one task on Dask distributed: a local "
        "cluster sized to this machine (one single-threaded worker process per core that "
        "memory allows), or an existing one with --scheduler. A failed session is reported "
        "with its error and the others go on; sessions already reconstructed are skipped. "
        "Each session's log is SESSION/recon/log.txt. Exit status 1 when any session failed, "
        "else 3 when one left unusable frames out (as `rig reconstruct`).",
    )
    parser.add_argument("sessions", nargs="*", type=Path, help="session folders")
    parser.add_argument(
        "--list",
        dest="list_file",
        type=Path,
        default=None,
        help="text file with one session folder per line (# comments; relative to the file)",
    )
    parser.add_argument(
        "--config",
        type=Path,
        default=None,
        help="reconstruct config (YAML) applied to every session, as for `rig reconstruct`",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        help="worker processes of the local cluster (default: cores, memory permitting)",
    )
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="use this running Dask scheduler (e.g. tcp://10.0.0.5:8786) instead of a local "
        "cluster; its workers must see the session folders at the same paths",
    )
    parser.add_argument(
        "--force", action="store_true", help="reconstruct sessions that already have outputs"
    )
    parser.add_argument(
        "--summary",
        type=Path,
        default=None,
        metavar="CSV",
        help="also write the summary table (all columns) to this CSV file",
    )
    parser.set_defaults(func=handle, stop_hint=stop_hint)


def stop_hint(args: argparse.Namespace) -> str:
    return "run the same `rig batch` again: finished sessions are skipped, the others resume"


def _run_batch() -> Callable[..., list[Outcome]]:
    """The Dask runner, imported only for this command: Dask is the `batch` extra."""
    try:
        from rig.batch.run import run_batch
    except ModuleNotFoundError as exc:
        if (exc.name or "").split(".")[0] not in ("dask", "distributed"):
            raise
        raise MissingDependencyError(
            "Dask distributed", "batch", "rig batch runs its sessions on a Dask cluster"
        ) from exc
    return run_batch


def handle(args: argparse.Namespace) -> int:
    run_batch = _run_batch()
    from reconstruct.run.pipeline import load_config
    from rig.batch.sessions import collect
    from rig.batch.summary import table, write_csv
    from rig.console import console as plain_console
    from rig.warmup import compile_kernels_once

    if args.workers is not None and not 1 <= args.workers <= MAX_WORKERS:
        raise RigError(f"--workers {args.workers} is out of range",
                       f"allowed: a whole number in [1, {MAX_WORKERS}]")
    if args.workers is not None and args.scheduler is not None:
        raise RigError(
            "--workers sizes a local cluster, but --scheduler names an existing one",
            "drop one of them",
        )
    if args.summary is not None:  # before hours of work, not after
        output_file(args.summary, "--summary")
    sessions = collect(args.sessions, args.list_file)
    config = load_config(args.config)
    console = plain_console(stderr=True)
    compile_kernels_once(console)  # once, not in every worker
    outcomes = run_batch(
        sessions, config, args.force, args.workers, args.scheduler, args.verbose, console
    )
    plain_console().print(table(outcomes))
    if args.summary is not None:
        console.print(f"summary: {write_csv(args.summary, outcomes)}", highlight=False)
    failed = [o for o in outcomes if o.status == "failed"]
    incomplete = [o for o in outcomes if o.status == "incomplete"]
    for outcome in failed + incomplete:
        console.print(
            f"{outcome.status}: {outcome.session}: {outcome.error}",
            highlight=False,
            markup=False,
            soft_wrap=True,
        )
    return 1 if failed else EXIT_SKIPPED_FRAMES if incomplete else 0
