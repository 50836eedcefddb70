"""The simulator is a driver like any other: nothing under rig/ knows a device is simulated
(ophyd.sim's habit: plans never know). The profile's ``sim`` section may still be read."""

from __future__ import annotations

import ast
from pathlib import Path

import rig

RIG = Path(rig.__file__).parent
SIM_NAMES = {"SimRig", "open_sim", "sim_config", "shared_rig"}


def _is_sim(node: ast.AST) -> bool:
    return isinstance(node, ast.Constant) and node.value == "sim"


def sim_mentions(source: str) -> list[str]:
    """Comparisons with "sim", imports of drivers.sim, ``<...devices>.sim`` and sim rig names."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare) and any(
            _is_sim(n) for n in (node.left, *node.comparators)
        ):
            found.append(f"line {node.lineno}: compares with 'sim'")
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("drivers.sim"):
            found.append(f"line {node.lineno}: imports {node.module}")
        elif isinstance(node, ast.Import) and any(
            a.name.startswith("drivers.sim") for a in node.names
        ):
            found.append(f"line {node.lineno}: imports drivers.sim")
        elif isinstance(node, ast.Attribute) and node.attr == "sim":
            owner = ast.unparse(node.value)
            if "device" in owner:
                found.append(f"line {node.lineno}: {owner}.sim")
        elif isinstance(node, ast.Name | ast.Attribute):
            name = node.id if isinstance(node, ast.Name) else node.attr
            if name in SIM_NAMES:
                found.append(f"line {node.lineno}: {name}")
    return found


def test_the_check_finds_sim_branches() -> None:
    source = (
        "import drivers.sim\n"
        "if spec.get('driver') == 'sim': pass\n"
        "if devices.sim is None: pass\n"
        "rig = open_sim(config, 0)\n"
    )
    assert len(sim_mentions(source)) == 4
    assert sim_mentions("section = profile.sim\nkeys = ('sim', 'board')\n") == []


def test_no_module_under_rig_knows_the_sim_driver() -> None:
    offenders = {
        str(path.relative_to(RIG.parent)): found
        for path in sorted(RIG.rglob("*.py"))
        if (found := sim_mentions(path.read_text(encoding="utf-8")))
    }
    assert offenders == {}
