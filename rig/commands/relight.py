"""`rig relight`: render the reconstruction under a new light."""

from __future__ import annotations

import argparse

from rig.commands._not_built import register


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    register(subparsers, "relight", "render the reconstruction under a new light", issue=6)
