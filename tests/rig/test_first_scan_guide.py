"""docs/first-scan.md works as written: its ```bash and ```python blocks run in order from an
empty folder on the simulated rig down to a GLB and a viewer page (the convention is in the
comment at the top of the guide), and the profiles' pointers into it land on its sections."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "first-scan.md"
RUNNABLE = ("bash", "python")
ILLUSTRATIONS = ("console", "yaml", "text")
FENCE = re.compile(r"^```(\w*)\n(.*?)^```$", re.MULTILINE | re.DOTALL)
GUIDE_LINK = re.compile(r"docs/first-scan\.md#([\w-]+)")


def guide_blocks() -> list[tuple[str, str]]:
    """(language, code) of every fenced block, in order."""
    return [(m.group(1), m.group(2)) for m in FENCE.finditer(GUIDE.read_text(encoding="utf-8"))]


def heading_anchors(markdown: str) -> set[str]:
    """GitHub's anchors of the headings: lower case, punctuation dropped, spaces -> '-'."""
    anchors = set()
    for line in markdown.splitlines():
        if line.startswith("#"):
            title = line.lstrip("#").strip().lower()
            anchors.add(re.sub(r"[^\w\- ]", "", title).replace(" ", "-"))
    return anchors


def test_every_block_follows_the_convention() -> None:
    blocks = guide_blocks()
    assert sum(lang in RUNNABLE for lang, _ in blocks) >= 8
    for lang, code in blocks:
        assert lang in RUNNABLE + ILLUSTRATIONS, f"block marked {lang!r}:\n{code}"
        if lang == "console":  # a real device's command, never run here
            assert code.startswith("# real hardware"), code


def test_the_profiles_point_to_sections_of_the_guide() -> None:
    anchors = heading_anchors(GUIDE.read_text(encoding="utf-8"))
    links = {}
    for profile in sorted((ROOT / "profiles").glob("*.yaml")):
        for anchor in GUIDE_LINK.findall(profile.read_text(encoding="utf-8")):
            links[f"{profile.name}#{anchor}"] = anchor in anchors
    assert links and all(links.values()), links
    placeholders = (ROOT / "profiles" / "bulb-gphoto2.yaml").read_text(encoding="utf-8")
    assert "REPLACE-WITH-LOCAL-KEY" in placeholders  # the guide explains these
    assert "REPLACE-WITH-LOCAL-KEY" in GUIDE.read_text(encoding="utf-8")


def test_the_readme_links_the_guide_after_its_opening_commands() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    second_command = readme.index("pip install -e '.[dev")
    link = readme.index("(docs/first-scan.md)")
    assert second_command < link < readme.index("## System requirements")


@pytest.mark.slow
def test_every_command_of_the_guide_runs_on_the_sim_rig(tmp_path: Path) -> None:
    work = tmp_path / "first scan"  # a space: the commands must not depend on the folder
    work.mkdir()
    env = {
        **os.environ,
        # the project's `rig` and `python` first, running this checkout's code
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
        "PYTHONPATH": str(ROOT),
        "SPECTRAL_RIG_STORE": str(tmp_path / "no-default-store"),  # never the user's store
        "SPECTRAL_RIG_WARMUP": "0",  # the reconstruction compiles its kernels in-process
        "NO_COLOR": "1",
    }
    for number, (lang, code) in enumerate(guide_blocks(), start=1):
        if lang not in RUNNABLE:
            continue
        command = (
            ["bash", "-euo", "pipefail", "-c", code] if lang == "bash"
            else [sys.executable, "-c", code]
        )
        proc = subprocess.run(
            command, cwd=work, env=env, capture_output=True, text=True, timeout=1200
        )
        assert proc.returncode == 0, (
            f"block {number} ({lang}) exited {proc.returncode}:\n{code}\n"
            f"stderr:\n{proc.stderr[-3000:]}"
        )
    glb = trimesh.load(work / "first-scan.glb", process=False)  # trimesh's glTF reader
    assert isinstance(glb, trimesh.Scene)
    (mesh,) = glb.geometry.values()
    assert len(mesh.vertices) > 1000 and len(mesh.faces) > 1000
    spectrum = np.ravel(mesh.vertex_attributes["_REFLECTANCE_550"])
    assert spectrum.shape == (len(mesh.vertices),) and np.all(np.isfinite(spectrum))
    assert mesh.visual.vertex_colors.shape == (len(mesh.vertices), 4)
    page = (work / "first-scan.html").read_text(encoding="utf-8")
    assert page.lstrip().lower().startswith("<!doctype html") and "</html>" in page
    assert (work / "first-scan-A.png").stat().st_size > 0
    assert (work / "board.pdf").read_bytes().startswith(b"%PDF")
    check = json.loads((work / "scans/chart/recon/chart_check/chart_check.json").read_text())
    assert len(check["patches"]) == 24
