"""`rig reconstruct`: reconstruct a mesh with per-vertex spectral reflectance."""

from __future__ import annotations

import argparse

from rig.commands._not_built import register


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    register(
        subparsers,
        "reconstruct",
        "reconstruct a mesh with per-vertex spectral reflectance",
        issue=6,
    )
