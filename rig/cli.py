"""`rig` entry point: global options, subcommand dispatch, one-line errors and stops.

Only the standard library and light modules are imported here: the signal handlers are in
place before anything heavy is, and `rig --help` builds its parser from light modules only
(each command imports what it needs when it runs).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import signal
import sys
from collections.abc import Sequence
from typing import NoReturn

from core import cachedir, interrupts
from core.errors import RigError
from core.fserrors import fs_error, underlying_fs_error
from core.text import printable
from rig import __version__

# Subcommand -> module in rig.commands exposing ``add_parser(subparsers)`` (``-`` -> ``_``).
COMMANDS: tuple[str, ...] = (
    "demo",
    "devices",
    "calibrate",
    "capture",
    "session",
    "reconstruct",
    "relight",
    "evaluate",
    "check-chart",
    "board",
    "batch",
    "view",
    "export",
)

log = logging.getLogger("rig")


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (argparse prints the usage block first)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {printable(message)} — see `{self.prog} --help`\n")


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
        module = importlib.import_module(f"rig.commands.{name.replace('-', '_')}")
        module.add_parser(subparsers)
    return parser


def configure_logging(verbosity: int, debug: bool) -> None:
    """Quiet by default: warnings only on the terminal, INFO with -v, DEBUG with -vv. The level
    is set on the handler too: loggers that write INFO to recon/log.txt (``reconstruct``) set
    their own level, and their records would otherwise reach the terminal as well."""
    from rich.console import Console
    from rich.logging import RichHandler

    level = logging.WARNING
    if verbosity == 1:
        level = logging.INFO
    elif verbosity >= 2 or debug:
        level = logging.DEBUG
    handler = RichHandler(console=Console(stderr=True), show_path=False)
    handler.setLevel(level)
    handler.setFormatter(_OneLineFormatter())
    logging.basicConfig(level=level, format="%(name)s: %(message)s", handlers=[handler], force=True)


class _OneLineFormatter(logging.Formatter):
    """A log message stays one line whatever the paths and names it holds (tracebacks, added
    after the message, keep their lines)."""

    def formatMessage(self, record: logging.LogRecord) -> str:
        return printable(super().formatMessage(record))


def main(argv: Sequence[str] | None = None) -> int:
    """Run one `rig` command and return its exit status: 128 + N after signal N (SIGINT 130,
    SIGTERM 143), with one line saying so, whatever the command was doing."""
    previous = interrupts.handlers()
    parsed: list[argparse.Namespace] = []  # the command line, once parsed
    try:
        interrupts.install()
        cachedir.direct_library_caches()  # before matplotlib or numba is imported
        try:
            code: int | None = _run(argv, parsed)
        except Exception as error:  # a failure a signal caused is reported as the signal
            code = None if interrupts.received() is not None else _report(error, parsed)
        if code is None or interrupts.received() is not None:
            return _stopped(parsed)  # the signal was taken by the command (the capture loop)
        return code
    except KeyboardInterrupt:
        return _stopped(parsed)
    finally:
        interrupts.restore(previous)


def run() -> NoReturn:
    """The `rig` program: a signal before the command starts or after it ends exits at once;
    a stopped command's process ends once the exit functions ran (``interrupts.exit_stopped``)."""
    interrupts.install(raising=False)
    status = main()
    if interrupts.was_stopped():
        interrupts.exit_stopped(status)
    sys.exit(status)


def _run(argv: Sequence[str] | None, parsed: list[argparse.Namespace]) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    parsed.append(args)
    configure_logging(args.verbose, args.debug)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    return int(args.func(args) or 0)


def _report(error: Exception, parsed: list[argparse.Namespace]) -> int:
    """One line for an error: 2 for one the user can fix, 1 for a bug."""
    from rich.console import Console
    from rich.text import Text

    debug = bool(parsed and parsed[0].debug)
    err = Console(stderr=True, soft_wrap=True)
    if debug:
        err.print_exception()
    cause = underlying_fs_error(error)
    if cause is not None and not isinstance(error, RigError):  # a full disk: the user's to fix
        error = fs_error(cause)
    # Text.assemble: `[gphoto2]` or `[/x]` in a message is printed, not taken as markup;
    # printable: a newline or escape sequence in a name does not break the one line
    if isinstance(error, RigError):
        err.print(Text.assemble(("error:", "bold red"), " ", printable(error)), highlight=False)
        return 2
    if not debug:
        err.print(
            Text.assemble(
                ("internal error:", "bold red"),
                f" {type(error).__name__}: {printable(error)} "
                "— run again with --debug for the traceback and report it",
            ),
            highlight=False,
        )
    return 1


def _stopped(parsed: list[argparse.Namespace]) -> int:
    """The line for a stop by signal, with how to resume when the command knows."""
    # a KeyboardInterrupt no handler of ours saw is Ctrl-C (at a prompt, in a thread)
    signum = interrupts.received() or signal.SIGINT
    interrupts.mark_stopped()  # before the hint, which may log
    hint = ""
    stop_hint = getattr(parsed[0], "stop_hint", None) if parsed else None
    if stop_hint is not None:
        try:
            hint = stop_hint(parsed[0])
        except Exception:  # the stop itself is what must be reported
            hint = ""
    print(printable(interrupts.stop_line(signum, hint)), file=sys.stderr, flush=True)
    return interrupts.exit_status(signum)


if __name__ == "__main__":
    run()
