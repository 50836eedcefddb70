"""`rig demo`: run the whole pipeline on the simulated rig."""

from __future__ import annotations

import argparse

from rig.commands._not_built import register


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    register(subparsers, "demo", "run the whole pipeline on the simulated rig", issue=6)
