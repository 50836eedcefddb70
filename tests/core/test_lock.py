"""core.lock: one writer per folder, a clear refusal naming the holder, no stale lock from a
dead process, re-entrant within a thread, waiting for the store's short changes."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from core.errors import RigError
from core.lock import LOCK_FILE, InUse, enclosing_session, locked, output_lock

ROOT = Path(__file__).parents[2]
HOLD = "import sys, time\nfrom core.lock import locked\nwith locked(sys.argv[1], 'rig capture'):\n"


def holder(folder: Path, body: str = "    print('held', flush=True); sys.stdin.read()\n"):
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD + body, str(folder)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env={"PYTHONPATH": str(ROOT)},
    )
    assert proc.stdout is not None and proc.stdout.readline() == "held\n"
    return proc


def test_a_second_process_is_refused_with_the_holder_in_one_line(tmp_path: Path) -> None:
    proc = holder(tmp_path)
    try:
        with pytest.raises(InUse) as info, locked(tmp_path, "rig reconstruct"):
            pass
        text = str(info.value)
        pattern = (
            rf"{re.escape(str(tmp_path))} is in use by `rig capture` \(PID {proc.pid} on "
            rf"{re.escape(socket.gethostname())}, since \d{{4}}-\d\d-\d\dT\d\d:\d\d:\d\dZ\) — "
            "wait for it to finish, or stop it"
        )
        assert re.fullmatch(pattern, text) and "\n" not in text
    finally:
        assert proc.stdin is not None
        proc.stdin.close()
        proc.wait()
    with locked(tmp_path, "rig reconstruct"):  # released with its process
        holder_record = json.loads((tmp_path / LOCK_FILE).read_text())
        assert holder_record["pid"] == os.getpid()
        assert holder_record["command"] == "rig reconstruct"
    assert not (tmp_path / LOCK_FILE).exists()  # a normal release leaves no file


def test_a_killed_holder_does_not_block(tmp_path: Path) -> None:
    proc = holder(tmp_path)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert json.loads((tmp_path / LOCK_FILE).read_text())["pid"] == proc.pid  # left behind
    with locked(tmp_path, "rig capture --resume"):
        assert json.loads((tmp_path / LOCK_FILE).read_text())["pid"] == os.getpid()


def test_a_lock_file_naming_a_dead_pid_does_not_block(tmp_path: Path) -> None:
    gone = subprocess.Popen(["true"])
    gone.wait()
    record = {"pid": gone.pid, "host": socket.gethostname(), "command": "rig capture",
              "since": "2026-01-01T00:00:00Z"}
    (tmp_path / LOCK_FILE).write_text(json.dumps(record))
    with locked(tmp_path, "rig reconstruct"):
        pass


def test_reentrant_in_a_thread_refused_in_another(tmp_path: Path) -> None:
    refused: list[BaseException] = []

    def other() -> None:
        try:
            with locked(tmp_path, "rig relight"):
                pass
        except InUse as error:
            refused.append(error)

    with locked(tmp_path, "rig capture"):
        with locked(tmp_path / ".", "rig reconstruct"):  # capture, then its reconstruction
            assert json.loads((tmp_path / LOCK_FILE).read_text())["command"] == "rig capture"
        assert (tmp_path / LOCK_FILE).exists()  # still held by the outer block
        thread = threading.Thread(target=other)
        thread.start()
        thread.join()
    assert len(refused) == 1 and f"PID {os.getpid()}" in str(refused[0])
    with locked(tmp_path, "rig relight"):  # free again
        pass


def test_a_waiting_change_gets_the_lock_when_the_holder_ends(tmp_path: Path) -> None:
    proc = holder(tmp_path, "    print('held', flush=True); sys.stdin.readline()\n")
    order: list[str] = []

    def end_holder() -> None:
        order.append("released")
        assert proc.stdin is not None
        proc.stdin.write("\n")
        proc.stdin.flush()

    timer = threading.Timer(0.3, end_holder)
    timer.start()
    with locked(tmp_path, "rig calibrate import", wait_s=60):
        order.append("acquired")
    timer.join()
    proc.wait()
    assert order == ["released", "acquired"]


def test_create_makes_the_folder_and_removes_it_if_left_empty(tmp_path: Path) -> None:
    folder = tmp_path / "a" / "new"
    with locked(folder, "rig capture", create=True):
        assert folder.is_dir()
    assert not (tmp_path / "a").exists()  # the parents it made too: nothing is left behind
    (tmp_path / "a").mkdir()
    with locked(folder, "rig capture", create=True):
        pass
    assert (tmp_path / "a").is_dir() and not folder.exists()  # what was there stays
    with locked(folder, "rig capture", create=True):
        (folder / "session.yaml").write_text("x")
    assert (folder / "session.yaml").is_file() and not (folder / LOCK_FILE).exists()


def test_a_missing_folder_or_a_bad_lock_file_is_one_clear_error(tmp_path: Path) -> None:
    with pytest.raises(RigError, match="cannot open the lock file .*missing"), locked(
        tmp_path / "missing", "rig reconstruct"
    ):
        pass
    (tmp_path / LOCK_FILE).mkdir()
    with pytest.raises(RigError, match=r"cannot open the lock file .*\.lock .* remove"), locked(
        tmp_path, "rig reconstruct"
    ):
        pass
    (tmp_path / LOCK_FILE).rmdir()
    victim = tmp_path.parent / f"{tmp_path.name}-victim"
    victim.write_text("precious")
    (tmp_path / LOCK_FILE).symlink_to(victim)
    with pytest.raises(RigError, match=r"cannot open the lock file"), locked(tmp_path, "x"):
        pass
    assert victim.read_text() == "precious"
    (tmp_path / LOCK_FILE).unlink()
    os.link(victim, tmp_path / LOCK_FILE)  # a hard link: writing the holder would change it
    with pytest.raises(RigError, match=r"\.lock has other names .* remove"), locked(tmp_path, "x"):
        pass
    assert victim.read_text() == "precious"
    (tmp_path / LOCK_FILE).unlink()
    os.mkfifo(tmp_path / LOCK_FILE)
    with pytest.raises(RigError, match=r"\.lock is not a plain file"), locked(tmp_path, "x"):
        pass


def test_output_lock_holds_the_enclosing_session_only(tmp_path: Path) -> None:
    session = tmp_path / "s"
    (session / "recon" / "relight").mkdir(parents=True)
    (session / "session.yaml").write_text("format: 1\n")
    png = session / "recon" / "relight" / "view000_D65.png"
    assert enclosing_session(png) == session
    assert enclosing_session(tmp_path / "elsewhere.png") is None
    with output_lock(png, "rig relight"):
        assert json.loads((session / LOCK_FILE).read_text())["command"] == "rig relight"
    with output_lock(tmp_path / "elsewhere.png", "rig relight"):
        assert not (tmp_path / LOCK_FILE).exists()
    proc = holder(session)
    try:
        with pytest.raises(InUse, match="in use by `rig capture`"), output_lock(png, "x"):
            pass
    finally:
        assert proc.stdin is not None
        proc.stdin.close()
        proc.wait()
