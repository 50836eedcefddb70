"""One `rig reconstruct` opens the session once, loads the poses stage's output once, and
writes report.json and timings.json once each; the stage files stay for resuming."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from recon_tiny import make_session, reconstruct_args

from core.files import write_bytes_atomically
from core.session import Session
from reconstruct.outputs import export
from reconstruct.poses import output as poses_output
from rig.cli import main


def test_one_reconstruction_opens_the_session_and_loads_poses_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session, config = make_session(tmp_path)
    calls: Counter[str] = Counter()
    opener = Session.open.__func__  # type: ignore[attr-defined]

    def counted_open(cls: type[Session], root: Path, bound_views: bool = True) -> Session:
        calls["open"] += 1
        return opener(cls, root, bound_views)  # type: ignore[no-any-return]

    reader = poses_output.read_colmap_text

    def counted_read(folder: Path) -> Any:
        calls["poses"] += 1
        return reader(folder)

    def counted_write(path: Path, data: bytes) -> None:
        calls[path.name] += 1
        write_bytes_atomically(path, data)

    monkeypatch.setattr(Session, "open", classmethod(counted_open))
    monkeypatch.setattr(poses_output, "read_colmap_text", counted_read)
    monkeypatch.setattr("reconstruct.stages.resumable.write_bytes_atomically", counted_write)
    writer = export.write_report

    def counted_report(path: Path, report: dict[str, Any]) -> Path:
        calls[path.name] += 1
        return writer(path, report)

    monkeypatch.setattr(export, "write_report", counted_report)
    assert main(reconstruct_args(session, config)) == 0
    assert calls["open"] == 1
    assert calls["poses"] == 1
    assert calls["timings.json"] == 1
    assert calls[export.REPORT_FILE] == 1
    recon = session / "recon"
    timings = json.loads((recon / "timings.json").read_text())
    assert {"decode", "poses", "visibility", "subdivide", "optimise", "export"} <= set(timings)
    assert (recon / "poses" / "poses.json").is_file()  # stage files stay for resuming
    assert (recon / "poses" / ".stamp.json").is_file()
