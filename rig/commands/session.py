"""`rig session`: inspect and verify a capture session."""

from __future__ import annotations

import argparse

from rig.commands._not_built import register


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    register(subparsers, "session", "inspect and verify a capture session", issue=4)
