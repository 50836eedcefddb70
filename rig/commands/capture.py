"""`rig capture`: guided capture session."""

from __future__ import annotations

import argparse

from rig.commands._not_built import register


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    register(subparsers, "capture", "guided capture session", issue=4)
