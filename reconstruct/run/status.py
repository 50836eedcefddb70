"""``recon/status.json``: whether a reconstruction is running, finished, failed or was killed.

A run writes ``running`` with its PID, host and the process's start time when it begins, the
stage it is in as it goes, and ``complete`` / ``failed`` / ``interrupted`` (Ctrl-C, SIGTERM) at
the end. A SIGKILL leaves ``running`` behind: :func:`read_status` reports such a run as
``interrupted`` once its process is gone (same host, PID not alive or reused). A run also holds
an exclusive lock on ``recon/.lock`` (released by the kernel however the process ends), so a
second run refuses to start while one is alive, and a ``running`` record left by a host whose
PIDs cannot be checked here (a container's new hostname, a cluster node) is known to be stale
once the lock is free.
"""

from __future__ import annotations

import fcntl
import json
import logging
import os
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from core import interrupts
from core.errors import RigError
from core.files import write_bytes_atomically

log = logging.getLogger("reconstruct")

FILE = "status.json"
LOCK = ".lock"


def _process_start(pid: int) -> str | None:
    """The process's start time in clock ticks since boot (``/proc``), to tell a reused PID."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]


def _alive(pid: int, started: str | None) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    now = _process_start(pid)
    return started is None or now is None or now == started


def read_status(recon_dir: Path) -> dict[str, Any] | None:
    """The status of the last run on ``recon_dir`` (None if none ran), with a ``running`` run
    whose process is gone on this host reported as ``interrupted``."""
    path = Path(recon_dir) / FILE
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as error:
        raise RigError(
            f"{path} is unreadable ({error})", "delete it; the next run writes a new one"
        ) from error
    if not isinstance(data, dict):
        raise RigError(f"{path} is not a status record", "delete it; the next run writes a new one")
    if (
        data.get("status") == "running"
        and data.get("host") == socket.gethostname()
        and not _alive(int(data.get("pid", -1)), data.get("process_start"))
    ):
        data["status"] = "interrupted"
        data["note"] = "the process is gone (killed or crashed)"
    return data


def describe(data: dict[str, Any] | None) -> str:
    """One line for the user."""
    if data is None:
        return "no reconstruction has run"
    where = f"pid {data.get('pid')} on {data.get('host')}, started {data.get('started')}"
    line = f"{data.get('status')} ({where}; stage {data.get('stage')})"
    if data.get("error"):
        line += f": {data['error']}"
    return line


def _already_running(recon_dir: Path, previous: dict[str, Any] | None) -> RigError:
    what = describe(previous) if previous else f"it holds {LOCK}"
    return RigError(
        f"a reconstruction is already running on {recon_dir} ({what})",
        "wait for it to finish or stop it first",
    )


class RunStatus:
    """The status record of this process's run on one recon folder."""

    def __init__(self, recon_dir: Path) -> None:
        self.path = Path(recon_dir) / FILE
        self.data: dict[str, Any] = {}
        self._lock: int | None = None

    def begin(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        previous = self._take_lock()
        if previous is not None and previous.get("status") == "running":
            same_host = previous.get("host") == socket.gethostname()
            if previous.get("pid") != os.getpid() and same_host:  # alive (read_status)
                self.release()
                raise _already_running(self.path.parent, previous)
            if not same_host:  # its lock is free: that run is gone
                previous.update(status="interrupted", note="its lock was free")
        if previous is not None and previous.get("status") == "interrupted":
            log.warning("the previous run was interrupted (%s): resuming", describe(previous))
        pid = os.getpid()
        self.data = {
            "status": "running",
            "pid": pid,
            "host": socket.gethostname(),
            "process_start": _process_start(pid),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "stage": "start",
            "previous": None if previous is None else previous.get("status"),
        }
        self._write()

    def _take_lock(self) -> dict[str, Any] | None:
        """Hold ``recon/.lock``; the previous status record, read under the lock."""
        fd = os.open(self.path.parent / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise _already_running(self.path.parent, read_status(self.path.parent)) from None
        self._lock = fd
        try:
            return read_status(self.path.parent)
        except RigError:
            self.release()
            raise

    def release(self) -> None:
        """Let the next run start (also done by the kernel when the process ends)."""
        if self._lock is not None:
            os.close(self._lock)
            self._lock = None

    def stage(self, name: str) -> None:
        self.data["stage"] = name
        self._write()

    def end(self, status: str, **extra: Any) -> None:
        self.data.update(status=status, finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"), **extra)
        self._write()

    def _write(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomically(self.path, (json.dumps(self.data, indent=2) + "\n").encode())

    def end_after_error(self, status: str, **extra: Any) -> None:
        """:meth:`end` while an error propagates: on a full disk, where no new file can be
        made, the record is rewritten in place (it fits the blocks it already has); if even
        that fails, a warning says so and the error being raised is what the user sees."""
        try:
            self.end(status, **extra)
        except RigError as error:
            text = (json.dumps(self.data, indent=2) + "\n").encode()
            try:
                fd = os.open(self.path, os.O_WRONLY | os.O_NOFOLLOW)
                try:
                    os.pwrite(fd, text, 0)
                    os.ftruncate(fd, len(text))
                    os.fsync(fd)
                finally:
                    os.close(fd)
            except OSError:
                log.warning("could not record the run as %s in %s: %s", status, self.path, error)


@contextmanager
def tracked(recon_dir: Path) -> Iterator[RunStatus]:
    """Run a block as a tracked reconstruction: ``running`` → ``complete`` (the block may end
    it otherwise), ``interrupted`` on Ctrl-C / SIGTERM, ``failed`` on an error."""
    status = RunStatus(recon_dir)
    status.begin()
    try:
        yield status
    except KeyboardInterrupt:
        status.end_after_error("interrupted", note="stopped by Ctrl-C or SIGTERM")
        raise
    except Exception as error:
        if interrupts.raised_by_a_stop(error) or interrupts.received() is not None:
            status.end_after_error("interrupted", note="stopped by Ctrl-C or SIGTERM")
        else:
            status.end_after_error("failed", error=" ".join(str(error).split()))
        raise
    else:
        if status.data["status"] == "running":
            status.end("complete")
    finally:
        status.release()
