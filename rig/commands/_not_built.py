"""Placeholder for subcommands whose issue has not landed: says so and exits non-zero."""

from __future__ import annotations

import argparse

from calibration.errors import RigError


def register(subparsers: argparse._SubParsersAction, name: str, help_text: str, issue: int) -> None:
    parser = subparsers.add_parser(name, help=f"{help_text} (not built yet)")
    parser.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)

    def run(_: argparse.Namespace) -> int:
        raise RigError(
            f"`rig {name}` is not built yet", f"it is tracked in issue #{issue}; nothing was done"
        )

    parser.set_defaults(func=run)
