"""Every `rig ...` command an error message or docstring tells the user to run exists (issue
17: `rig calibrate light` was named in a fix but did not exist)."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from rig.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("calibration", "drivers", "reconstruct", "rig")
COMMAND = re.compile(r"`rig ([a-z][a-z-]*)(?: ([a-z][a-z-]*))?")


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def test_every_rig_command_named_in_the_source_exists() -> None:
    top = subcommands(build_parser())
    named: set[tuple[str, str | None]] = set()
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            named.update(COMMAND.findall(path.read_text(encoding="utf-8")))
    assert ("calibrate", "wizard") in {(a, b or None) for a, b in named}
    missing = []
    for command, action in sorted(named):
        if command not in top:
            missing.append(f"rig {command}")
            continue
        actions = subcommands(top[command])
        if actions and action and action not in actions:
            missing.append(f"rig {command} {action}")
    assert not missing, f"named in messages but not commands: {missing}"
