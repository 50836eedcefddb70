"""`rig devices`: list connected devices and the driver that fits each."""

from __future__ import annotations

import argparse

from rig.commands._not_built import register


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    register(subparsers, "devices", "list connected devices and the driver that fits each", issue=3)
