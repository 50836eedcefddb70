"""`rig board`: print a ChArUco marker board for poses and metric scale."""

from __future__ import annotations

import argparse

from rig.commands._not_built import register


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    register(subparsers, "board", "generate a printable ChArUco marker board", issue=9)
