"""Every library call that writes into a session takes its lock (core.lock), so a library
user is refused like the CLI: relight's PNG, evaluate's files, the exported viewer page, a
reconstruction (`run_logged`, `run_reconstruction`) and a `rig batch` task."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from lockholder import hold, release_all

from core.lock import LOCK_FILE, InUse
from reconstruct.outputs.evaluate import evaluate
from reconstruct.outputs.relight import write_png
from reconstruct.run.logfile import run_logged
from reconstruct.run.pipeline import run_reconstruction
from rig.batch.task import reconstruct_session
from rig.view.page import export_page

IN_USE = r"is in use by `rig capture` \(PID \d+"


@pytest.fixture
def held(tmp_path: Path) -> Iterator[Path]:
    session = tmp_path / "s"
    (session / "recon").mkdir(parents=True)
    (session / "session.yaml").write_text("format: 1\n")
    hold(session)
    yield session
    release_all()


def test_writers_into_a_held_session_are_refused(held: Path) -> None:
    with pytest.raises(InUse, match=IN_USE):
        write_png(held / "recon" / "relight" / "view000_D65.png", np.zeros((2, 2, 3), np.uint8))
    with pytest.raises(InUse, match=IN_USE):
        export_page(held / "viewer.html", "<html></html>")
    with pytest.raises(InUse, match=IN_USE):
        evaluate(held / "recon", held / "gt.ply", held / "gt.npy")
    for reconstruct in (run_logged, run_reconstruction):
        with pytest.raises(InUse, match=IN_USE):
            reconstruct(held)
    outcome = reconstruct_session(str(held), {}, force=False, verbosity=0)
    assert outcome.status == "failed" and "in use by `rig capture`" in outcome.error
    assert sorted(p.name for p in held.rglob("*")) == [LOCK_FILE, "recon", "session.yaml"]


def test_writers_outside_a_session_take_no_lock(tmp_path: Path) -> None:
    export_page(tmp_path / "out" / "viewer.html", "<html></html>")
    write_png(tmp_path / "a.png", np.zeros((2, 2, 3), np.uint8))
    assert (tmp_path / "out" / "viewer.html").read_text() == "<html></html>"
    assert not (tmp_path / LOCK_FILE).exists()
