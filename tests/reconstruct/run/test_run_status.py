"""recon/status.json (a killed run reads `interrupted`, a live one blocks a second run), the
export swap (old and new outputs never mixed), and the duplicate-key YAML loader."""

from __future__ import annotations

import json
import os
import socket
import subprocess
from pathlib import Path

import pytest
import yaml

from core.errors import RigError
from core.yamlio import load_yaml, read_yaml
from reconstruct.run.status import FILE, RunStatus, describe, read_status, tracked
from reconstruct.stages import publish


def status_of(recon: Path, pid: int) -> None:
    recon.mkdir(parents=True, exist_ok=True)
    record = {"status": "running", "pid": pid, "host": socket.gethostname(), "stage": "optimise"}
    (recon / FILE).write_text(json.dumps(record))


def test_a_killed_run_reads_interrupted(tmp_path: Path) -> None:
    proc = subprocess.Popen(["sleep", "0"])
    proc.wait()  # its PID is gone now
    status_of(tmp_path, proc.pid)
    data = read_status(tmp_path)
    assert data is not None and data["status"] == "interrupted"
    assert "interrupted" in describe(data) and "optimise" in describe(data)


def test_a_live_run_blocks_a_second_one(tmp_path: Path) -> None:
    proc = subprocess.Popen(["sleep", "30"])
    try:
        status_of(tmp_path, proc.pid)
        assert read_status(tmp_path)["status"] == "running"  # type: ignore[index]
        with pytest.raises(RigError, match="already running"):
            RunStatus(tmp_path).begin()
    finally:
        proc.kill()
        proc.wait()
    RunStatus(tmp_path).begin()  # gone: the new run takes over
    assert read_status(tmp_path)["pid"] == os.getpid()  # type: ignore[index]


def test_a_run_holding_the_lock_blocks_a_second_one(tmp_path: Path) -> None:
    first = RunStatus(tmp_path)
    first.begin()
    with pytest.raises(RigError, match="already running"):
        RunStatus(tmp_path).begin()
    first.release()
    RunStatus(tmp_path).begin()


def test_a_stale_record_from_another_host_does_not_block_forever(tmp_path: Path) -> None:
    """A container's new hostname, or a cluster node: its PID cannot be checked here, but the
    lock it held died with it."""
    record = {"status": "running", "pid": 1, "host": "elsewhere", "stage": "optimise"}
    (tmp_path / FILE).write_text(json.dumps(record))
    with tracked(tmp_path) as status:
        assert status.data["previous"] == "interrupted"
    assert read_status(tmp_path)["status"] == "complete"  # type: ignore[index]


def test_tracked_records_complete_failed_and_interrupted(tmp_path: Path) -> None:
    with tracked(tmp_path):
        pass
    assert read_status(tmp_path)["status"] == "complete"  # type: ignore[index]
    with pytest.raises(ValueError), tracked(tmp_path):
        raise ValueError("bad\nthing")
    data = read_status(tmp_path)
    assert data is not None and data["status"] == "failed" and data["error"] == "bad thing"
    with pytest.raises(KeyboardInterrupt), tracked(tmp_path):
        raise KeyboardInterrupt
    assert read_status(tmp_path)["status"] == "interrupted"  # type: ignore[index]


def test_an_error_raised_while_a_stop_unwinds_is_recorded_as_interrupted(tmp_path: Path) -> None:
    def library_call() -> None:
        try:
            raise KeyboardInterrupt  # SIGTERM arrives inside a library ...
        except BaseException as stop:
            raise RuntimeError("native call aborted") from stop  # ... which raises its own

    with pytest.raises(RuntimeError), tracked(tmp_path):
        library_call()
    assert read_status(tmp_path)["status"] == "interrupted"  # type: ignore[index]
    with pytest.raises(RuntimeError), tracked(tmp_path):
        try:
            raise KeyboardInterrupt
        finally:
            raise RuntimeError("cleanup failed on the way out")
    assert read_status(tmp_path)["status"] == "interrupted"  # type: ignore[index]


def test_an_unreadable_status_is_a_clear_error(tmp_path: Path) -> None:
    (tmp_path / FILE).write_text("{torn")
    with pytest.raises(RigError, match="status.json is unreadable"):
        read_status(tmp_path)


def stage(recon: Path, files: dict[str, str]) -> Path:
    staging = publish.staging_dir(recon)
    for name, text in files.items():
        (staging / name).write_text(text)
    return staging


def test_publish_swaps_the_whole_set(tmp_path: Path) -> None:
    publish.publish(tmp_path, stage(tmp_path, {"mesh.ply": "old", "preview_view005.png": "old"}))
    assert publish.published(tmp_path) == ["mesh.ply", "preview_view005.png"]
    publish.publish(tmp_path, stage(tmp_path, {"mesh.ply": "new", "report.json": "new"}))
    assert publish.published(tmp_path) == ["mesh.ply", "report.json"]
    assert not (tmp_path / "preview_view005.png").exists()  # no stale file of the old set
    assert (tmp_path / "mesh.ply").read_text() == "new"


def test_publish_keeps_the_persons_files_and_drops_a_stale_evaluation(tmp_path: Path) -> None:
    publish.publish(tmp_path, stage(tmp_path, {"mesh.ply": "old"}))
    for name in (*publish.EVALUATION, "notes.png"):  # rig evaluate's files, and the person's
        (tmp_path / name).write_text("of the old set")
    publish.publish(tmp_path, stage(tmp_path, {"mesh.ply": "new"}))
    assert (tmp_path / "notes.png").read_text() == "of the old set"
    assert not any((tmp_path / name).exists() for name in publish.EVALUATION)


def test_a_crash_mid_swap_leaves_no_mix_and_no_marker(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    publish.publish(tmp_path, stage(tmp_path, {"a.png": "old", "mesh.ply": "old"}))
    staging = stage(tmp_path, {"a.png": "new", "mesh.ply": "new"})
    calls = {"n": 0}
    real = Path.replace

    def replace(self: Path, target: Path) -> Path:  # dies on the first move of a new file
        if self.parent == staging:
            calls["n"] += 1
            if calls["n"] == 2:
                raise KeyboardInterrupt
        return real(self, target)

    monkeypatch.setattr(Path, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        publish.publish(tmp_path, staging)
    monkeypatch.undo()
    assert publish.published(tmp_path) is None
    texts = {p.read_text() for p in tmp_path.iterdir() if p.is_file()}
    assert texts == {"new"}  # one new file moved in, no old one left beside it
    publish.publish(tmp_path, stage(tmp_path, {"a.png": "new", "mesh.ply": "new"}))
    assert publish.published(tmp_path) == ["a.png", "mesh.ply"]
    assert not (tmp_path / publish.OLD).exists()


def test_duplicate_keys_are_rejected_but_merges_allowed(tmp_path: Path) -> None:
    with pytest.raises(yaml.YAMLError, match="duplicate key 'a' \\(first at line 1\\)"):
        load_yaml("a: 1\nb: 2\na: 3\n")
    with pytest.raises(yaml.YAMLError, match="duplicate key 'x'"):
        load_yaml("top:\n  - {x: 1, x: 2}\n")
    assert load_yaml("base: &b {x: 1, y: 2}\nd:\n  <<: *b\n  x: 5\n")["d"] == {"x": 5, "y": 2}
    path = tmp_path / "p.yaml"
    path.write_text("a: 1\na: 2\n")
    with pytest.raises(RigError) as info:
        read_yaml(path, "profile", "fix it")
    assert "\n" not in str(info.value) and "line 2" in str(info.value)
