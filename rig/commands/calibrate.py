"""`rig calibrate`: spectral calibration store, basis and illumination selection."""

from __future__ import annotations

import argparse

from rig.commands._not_built import register


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    register(
        subparsers,
        "calibrate",
        "spectral calibration store, basis and illumination selection",
        issue=2,
    )
