"""`rig` entry point: global options, subcommand dispatch, one-line errors."""

from __future__ import annotations

import argparse
import importlib
import logging
import signal
import sys
import threading
from collections.abc import Sequence
from types import FrameType
from typing import NoReturn

from rich.console import Console
from rich.logging import RichHandler
from rich.text import Text

from core.errors import RigError
from rig import __version__

# Subcommand -> module in rig.commands exposing ``add_parser(subparsers)``.
COMMANDS: tuple[str, ...] = (
    "demo",
    "devices",
    "calibrate",
    "capture",
    "session",
    "reconstruct",
    "relight",
    "evaluate",
    "board",
    "batch",
    "view",
    "export",
)

log = logging.getLogger("rig")


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (argparse prints the usage block first)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} — see `{self.prog} --help`\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="rig",
        description="Spectral multi-view inverse rendering with an RGB camera and an LED light.",
    )
    parser.add_argument("--version", action="version", version=f"spectral-rig {__version__}")
    parser.add_argument(
        "-v", "--verbose", action="count", default=0, help="more logging (-vv for debug)"
    )
    parser.add_argument(
        "--debug", action="store_true", help="show tracebacks and debug logging on errors"
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        module = importlib.import_module(f"rig.commands.{name}")
        module.add_parser(subparsers)
    return parser


def configure_logging(verbosity: int, debug: bool) -> None:
    """Quiet by default: warnings only on the terminal, INFO with -v, DEBUG with -vv. The level
    is set on the handler too: loggers that write INFO to recon/log.txt (``reconstruct``) set
    their own level, and their records would otherwise reach the terminal as well."""
    level = logging.WARNING
    if verbosity == 1:
        level = logging.INFO
    elif verbosity >= 2 or debug:
        level = logging.DEBUG
    handler = RichHandler(console=Console(stderr=True), show_path=False)
    handler.setLevel(level)
    logging.basicConfig(level=level, format="%(name)s: %(message)s", handlers=[handler], force=True)


class Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C: stages unwind, save their state and the CLI exits 143."""


def _terminate(signum: int, frame: FrameType | None) -> None:
    raise Terminated


def handle_sigterm() -> None:
    """Route SIGTERM to :class:`Terminated`. pycolmap's glog installs a C-level handler on
    import that prints a native stack dump on SIGTERM; importing it first lets ours replace it."""
    import pycolmap  # noqa: F401  (its import installs the handler ours must override)

    if threading.current_thread() is threading.main_thread():  # signals go to the main thread
        signal.signal(signal.SIGTERM, _terminate)


def _line(label: str, style: str, message: str) -> Text:
    """One error line printed literally: `[gphoto2]` or `[/x]` in a message is not markup."""
    return Text.assemble((label, style), " ", message)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    configure_logging(args.verbose, args.debug)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    err = Console(stderr=True, soft_wrap=True)
    previous = signal.getsignal(signal.SIGTERM)
    handle_sigterm()
    try:
        result = args.func(args)
        return int(result or 0)
    except RigError as error:
        if args.debug:
            err.print_exception()
        err.print(_line("error:", "bold red", str(error)), highlight=False)
        return 2
    except Terminated:
        err.print(_line("terminated", "yellow", "(SIGTERM): state saved; run again to resume"))
        return 143
    except KeyboardInterrupt:
        err.print("[yellow]interrupted[/]")
        return 130
    except Exception as error:
        if args.debug:
            err.print_exception()
        else:
            err.print(
                _line(
                    "internal error:",
                    "bold red",
                    f"{type(error).__name__}: {error} "
                    "— run again with --debug for the traceback and report it",
                ),
                highlight=False,
            )
        return 1
    finally:
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, previous if previous is not None else signal.SIG_DFL)


if __name__ == "__main__":
    sys.exit(main())
