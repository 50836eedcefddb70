"""`rig reconstruct` in its own process on a tiny simulated session, SIGKILLed 20 times at
seeded random instants inside its stages (front, optimisation, export): after every kill the
status file says `interrupted` (or `complete` when the kill landed as a finished run exited),
the outputs are either a complete published set or none (never a mix), the checkpoint is
readable; the run then resumes to the same numbers as an uninterrupted run."""

from __future__ import annotations

import json
import os
import shutil
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from recon_tiny import make_session, reconstruct_args, spawn

from reconstruct.optimise.checkpoint import FILE as CHECKPOINT
from reconstruct.outputs import export
from reconstruct.run.status import read_status
from reconstruct.stages import publish
from rig.cli import main

pytest.importorskip("drivers.sim")
KILLS = 20
# Where to kill -> the longest random delay (s) after reaching it; "mid-solve": the optimise
# stage once a checkpoint of a completed solver stage exists (a resumed solve is killed again).
TARGETS = {"front": 0.2, "optimise": 2.0, "mid-solve": 0.5, "export": 1.5}
OUTPUT_PATTERNS = ("mesh.ply", "reflectance.npz", "report.json", "*.png")


def stage_of(recon: Path, pid: int) -> str | None:
    try:
        data = json.loads((recon / "status.json").read_text())
    except (OSError, ValueError):
        return None
    return str(data["stage"]) if data.get("pid") == pid else None


def reached(recon: Path, pid: int, target: str) -> bool:
    stage = stage_of(recon, pid)
    if target != "mid-solve":
        return stage == target
    return stage == "optimise" and (recon / "optimise" / CHECKPOINT).is_file()


def checkpoint_state(recon: Path) -> str:
    path = recon / "optimise" / CHECKPOINT
    if not path.is_file():
        return "none"
    with np.load(path) as data:  # readable after any kill
        meta = json.loads(str(data["meta"]))
    return "done" if meta["done"] else f"after stage {meta['stage']}"


def assert_never_mixed(recon: Path) -> None:
    """A marker lists exactly the outputs present; without one the export is redone."""
    present = {p.name for pat in OUTPUT_PATTERNS for p in recon.glob(pat)}
    listed = publish.published(recon)
    if listed is None:
        assert not (recon / publish.MARKER).exists()
        return
    assert set(listed) == present
    json.loads((recon / export.REPORT_FILE).read_text())
    export.read_reflectance_npz(recon / export.REFLECTANCE_FILE)


@pytest.mark.slow
def test_twenty_sigkills_never_mix_outputs_and_resume_to_the_same_result(
    tmp_path: Path,
) -> None:
    session, config = make_session(tmp_path)
    clean = tmp_path / "clean"
    shutil.copytree(session, clean)
    assert main(reconstruct_args(clean, config)) == 0
    reference = export.read_reflectance_npz(clean / "recon" / export.REFLECTANCE_FILE)
    ref_report = json.loads((clean / "recon" / export.REPORT_FILE).read_text())

    rng = np.random.default_rng(17)
    recon = session / "recon"
    kills: list[tuple[str, float, str]] = []  # (stage, delay, checkpoint after the kill)
    while len(kills) < KILLS:
        target = str(rng.choice(list(TARGETS)))
        delay = float(rng.uniform(0.0, TARGETS[target]))
        if target == "front":  # cached stages take no time: make the decode stage run again
            shutil.rmtree(recon / "decoded", ignore_errors=True)
        proc = spawn(reconstruct_args(session, config))
        deadline = time.monotonic() + 120
        while proc.poll() is None and not reached(recon, proc.pid, target):
            assert time.monotonic() < deadline, "reconstruct made no progress"
            time.sleep(0.01)
        time.sleep(delay)
        if proc.poll() is not None:  # it finished before the kill
            assert proc.wait() == 0, proc.stderr.read().decode() if proc.stderr else ""
            if rng.random() < 0.5:  # solve again, so kills land inside it
                (recon / "optimise" / CHECKPOINT).unlink(missing_ok=True)
            continue
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        status = read_status(recon)
        assert status is not None, "a killed run left no status"
        assert_never_mixed(recon)
        if status["status"] == "complete":  # the kill landed while the finished run exited
            continue
        assert status["status"] == "interrupted", status
        saved = checkpoint_state(recon)
        if saved == "done" and rng.random() < 0.5:  # solve again, so kills land inside it
            (recon / "optimise" / CHECKPOINT).unlink()
        kills.append((status["stage"], round(delay, 2), saved))
    print("kills (stage, delay s, checkpoint):", kills)
    assert {k[0] for k in kills} == {"front", "optimise", "export"}
    assert any(k[0] == "optimise" and k[2].startswith("after") for k in kills)  # mid-solve

    assert main(reconstruct_args(session, config)) == 0
    status = read_status(recon)
    assert status is not None and status["status"] == "complete"
    assert_never_mixed(recon)
    assert not (recon / publish.STAGING).exists() and not (recon / publish.OLD).exists()
    result = export.read_reflectance_npz(recon / export.REFLECTANCE_FILE)
    for key in ("vertices", "faces", "reflectance", "alpha", "observed"):
        np.testing.assert_array_equal(result[key], reference[key], err_msg=key)
    report = json.loads((recon / export.REPORT_FILE).read_text())
    assert report["light"] == ref_report["light"]
    untimed = [[{k: v for k, v in h.items() if k != "seconds"} for h in r["history"]]
               for r in (report, ref_report)]
    assert untimed[0] == untimed[1]  # the same iterations with the same costs


@pytest.mark.slow
def test_sigterm_exits_143_without_a_stack_dump_and_resumes(tmp_path: Path) -> None:
    """pycolmap's glog prints a native stack dump on SIGTERM; the CLI handles it like Ctrl-C."""
    session, config = make_session(tmp_path)
    recon = session / "recon"
    proc = spawn(reconstruct_args(session, config))
    deadline = time.monotonic() + 120
    while proc.poll() is None and stage_of(recon, proc.pid) != "optimise":
        assert time.monotonic() < deadline, "reconstruct made no progress"
        time.sleep(0.01)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    text = err.decode()
    assert proc.returncode == 143, text
    assert "stack trace" not in text and "*** SIGTERM" not in text and "Traceback" not in text
    assert text.rstrip().splitlines()[-1].startswith("rig: stopped by SIGTERM (exit 143)")
    status = read_status(recon)
    assert status is not None and status["status"] == "interrupted"
    assert main(reconstruct_args(session, config)) == 0
    assert read_status(recon)["status"] == "complete"  # type: ignore[index]
