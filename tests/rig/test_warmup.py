"""The kernel warm-up: a stamped cache skips the child, a finished child stamps it, a failed one
only warns, the key follows the kernel sources, and the child fills an empty numba cache."""

from __future__ import annotations

import io
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest
from rich.console import Console

from rig import warmup


@pytest.fixture
def stamp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    path = tmp_path / "cache" / warmup.STAMP_FILE
    path.parent.mkdir()
    monkeypatch.setattr(warmup, "stamp_path", lambda: path)
    monkeypatch.setenv("SPECTRAL_RIG_WARMUP", "1")
    return path


def counting_child(runs: Path, code: int = 0) -> list[str]:
    """A child that appends a line to ``runs`` and exits with ``code``."""
    script = (
        f"open({str(runs)!r}, 'a').write('run\\n'); import sys; "
        f"sys.stderr.write('numba: no such kernel\\n'); sys.exit({code})"
    )
    return [sys.executable, "-c", script]


def test_a_finished_child_stamps_the_cache_and_is_not_run_again(stamp: Path, tmp_path: Path):
    runs = tmp_path / "runs.txt"
    console = Console(file=io.StringIO(), width=200)
    assert warmup.compile_kernels_once(console, command=counting_child(runs))
    assert "compiling the numerical kernels once" in console.file.getvalue()
    assert json.loads(stamp.read_text())["key"] == warmup.warmup_key()
    assert warmup.compile_kernels_once(command=counting_child(runs))
    assert runs.read_text().splitlines() == ["run"]


def test_a_failed_child_warns_and_leaves_no_stamp(
    stamp: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
):
    runs = tmp_path / "runs.txt"
    with caplog.at_level(logging.WARNING, logger="rig.warmup"):
        assert not warmup.compile_kernels_once(command=counting_child(runs, code=3))
    assert "exited 3" in caplog.text and "numba: no such kernel" in caplog.text
    assert not stamp.exists()
    assert not warmup.compile_kernels_once(command=counting_child(runs, code=3))
    assert len(runs.read_text().splitlines()) == 2  # tried again next time


def test_a_stale_stamp_runs_the_child(stamp: Path, tmp_path: Path):
    stamp.write_text(json.dumps({"key": "kernels of an older install"}))
    runs = tmp_path / "runs.txt"
    assert warmup.compile_kernels_once(command=counting_child(runs))
    assert runs.exists()


def test_the_switch_turns_the_step_off(stamp: Path, tmp_path: Path, monkeypatch):
    monkeypatch.setenv("SPECTRAL_RIG_WARMUP", "0")
    runs = tmp_path / "runs.txt"
    assert not warmup.compile_kernels_once(command=counting_child(runs))
    assert not runs.exists() and not stamp.exists()


def test_the_key_follows_the_kernel_sources(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    (tmp_path / "fake_kernels.py").write_text("def kernel(): return 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(warmup, "KERNEL_MODULES", ("fake_kernels",))
    before = warmup.warmup_key()
    assert warmup.warmup_key() == before
    (tmp_path / "fake_kernels.py").write_text("def kernel(): return 2\n")
    assert warmup.warmup_key() != before


def test_the_stamp_sits_in_numbas_cache_folder(tmp_path: Path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run(
        [sys.executable, "-c", "from rig.warmup import stamp_path; print(stamp_path())"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    assert Path(out.stdout.strip()).parent.parent == tmp_path


@pytest.mark.slow
def test_the_child_fills_an_empty_numba_cache(tmp_path: Path):
    """The child reconstructs its tiny capture and leaves the dense path's and the optimiser's
    kernels cached (the folder numba would otherwise fill during the user's run)."""
    cache, scratch = tmp_path / "cache", tmp_path / "tmp"
    scratch.mkdir()
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "TMPDIR": str(scratch)}
    subprocess.run(warmup.CHILD, env=env, check=True, capture_output=True, timeout=900)
    cached = {p.name.split("-")[0] for p in cache.rglob("*.nbi")}
    for kernel in (
        "normal_equations.gram_products",
        "normal_equations.accumulate_normal_equations",
        "sampling._sample_bilinear",
        "preconditioner.solve_vertex_blocks",
        "plane_cost.sweep",
        "board_silhouette._ground_coverage",
    ):
        assert kernel in cached
    assert not list(scratch.iterdir())  # its capture is gone


def test_a_wrong_session_fails_before_the_warm_up(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
):
    """A typo in the session path on a fresh install is reported at once, not after ~1 min."""
    from rig import cli, warmup

    calls: list[object] = []
    monkeypatch.setattr(warmup, "compile_kernels_once", calls.append)
    assert cli.main(["reconstruct", str(tmp_path / "nowhere")]) != 0
    assert "is not a session directory" in capsys.readouterr().err
    assert calls == []


class ReleasingLog(io.StringIO):
    """A log file that lets the child finish once a periodic progress line reached it."""

    def __init__(self, release: Path) -> None:
        super().__init__()
        self.release = release

    def write(self, text: str) -> int:
        if "] compiling kernels" in text:
            self.release.touch()
        return super().write(text)


def test_on_a_log_the_wait_prints_periodic_plain_lines(
    stamp: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    monkeypatch.setattr(warmup, "PROGRESS_EVERY_S", 0.01)
    release = tmp_path / "release"
    wait = (
        f"import os, time\nfor _ in range(3000):\n"
        f"    if os.path.exists({str(release)!r}): break\n    time.sleep(0.01)"
    )
    child = [sys.executable, "-c", wait]  # gives up after a while: no line must fail, not hang
    log = ReleasingLog(release)
    assert warmup.compile_kernels_once(Console(file=log, width=200), command=child)
    text = log.getvalue()
    assert text.startswith("compiling the numerical kernels once")
    assert "] compiling kernels" in text and "\x1b[" not in text
