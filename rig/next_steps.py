"""What to run after `rig demo`: the commands that open its result, with its own paths."""

from __future__ import annotations

import shlex
from pathlib import Path


def next_commands(out: Path, view: int) -> list[tuple[str, str]]:
    """(command, what it does) for the demo's output folder ``out``; ``view``: a posed view."""
    folder = shlex.quote(str(out))
    glb = shlex.quote(str(out / "model.glb"))
    return [
        (f"rig view {folder}", "the mesh and its per-vertex spectra in the browser"),
        (f"rig relight {folder} --view {view} --illuminant A", "a captured view under lamp A"),
        (f"rig export {folder} --glb {glb}", "glTF for Blender, three.js or a web viewer"),
        (f"rig session info {folder}", "what was captured"),
    ]
