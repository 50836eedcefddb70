"""Resumable stages: skip on the same conf + inputs, re-run on a change, timings recorded."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from reconstruct.stages.resumable import run_stage, stage_hash


def test_skips_reruns_and_times(tmp_path: Path) -> None:
    src = tmp_path / "in.txt"
    src.write_text("a")
    out = tmp_path / "recon" / "stage"
    calls: list[int] = []

    def work() -> None:
        calls.append(1)
        (out / "result.txt").write_text(src.read_text())

    assert not run_stage("s", {"k": 1}, [src], out, work).skipped
    assert run_stage("s", {"k": 1}, [src], out, work).skipped
    assert len(calls) == 1
    assert not run_stage("s", {"k": 2}, [src], out, work).skipped  # conf changed
    src.write_text("bb")
    os.utime(src, ns=(1, 10**18))
    assert not run_stage("s", {"k": 2}, [src], out, work).skipped  # input changed
    assert len(calls) == 3
    timings = json.loads((tmp_path / "recon" / "timings.json").read_text())
    assert timings["s"]["skipped"] is False and timings["s"]["seconds"] >= 0


def test_interrupted_stage_runs_again(tmp_path: Path) -> None:
    out = tmp_path / "recon" / "stage"

    def crash() -> None:
        raise KeyboardInterrupt

    try:
        run_stage("s", {}, [], out, crash)
    except KeyboardInterrupt:
        pass
    assert not (out / ".stamp.json").exists()
    assert not run_stage("s", {}, [], out, lambda: None).skipped


def test_an_input_hashes_alike_however_its_path_is_spelled(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "session").mkdir()
    (tmp_path / "session" / "frame.npy").write_bytes(b"x")
    monkeypatch.chdir(tmp_path)
    absolute = stage_hash({"a": 1}, [tmp_path / "session" / "frame.npy"])
    assert stage_hash({"a": 1}, [Path("session/frame.npy")]) == absolute
    assert stage_hash({"a": 1}, [Path("session/../session/frame.npy")]) == absolute
    assert stage_hash({"a": 2}, [Path("session/frame.npy")]) != absolute
