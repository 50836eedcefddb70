"""`rig evaluate`: compare a reconstruction with ground truth."""

from __future__ import annotations

import argparse

from rig.commands._not_built import register


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    register(subparsers, "evaluate", "compare a reconstruction with ground truth", issue=6)
