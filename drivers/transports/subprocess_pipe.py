"""A helper program's stdin/stdout as a byte channel (vendor CLIs, OLA clients, bridges)."""

from __future__ import annotations

import os
import select
import shlex
import subprocess
import tempfile
from collections.abc import Sequence

from core.errors import RigError
from drivers.transports.base import Transport


class SubprocessTransport(Transport):
    kind = "subprocess"

    def __init__(self, command: str | Sequence[str], timeout_s: float = 2.0) -> None:
        argv = shlex.split(command) if isinstance(command, str) else list(command)
        super().__init__(" ".join(argv), timeout_s)
        # stderr goes to a file, not a pipe nobody drains: a chatty helper would block on a
        # full pipe and look like a silent device; the file's tail explains an exit.
        self._stderr = tempfile.TemporaryFile()
        try:
            self._proc = subprocess.Popen(
                argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._stderr
            )
        except FileNotFoundError as error:
            self._stderr.close()
            raise RigError(
                f"program {argv[0]!r} not found", "install it or give its full path in the profile"
            ) from error
        except PermissionError as error:
            self._stderr.close()
            raise RigError(f"program {argv[0]!r} is not executable", "chmod +x it") from error

    def _check_alive(self) -> None:
        code = self._proc.poll()
        if code is not None:
            self._stderr.seek(0)
            tail = self._stderr.read().decode(errors="replace").strip()[-300:]
            raise RigError(
                f"helper program `{self.address}` exited with status {code}"
                + (f": {tail}" if tail else ""),
                "run it by hand to see why",
            )

    def _write(self, data: bytes) -> None:
        self._check_alive()
        assert self._proc.stdin is not None
        try:
            self._proc.stdin.write(data)
            self._proc.stdin.flush()
        except BrokenPipeError as error:
            self._check_alive()
            raise RigError(
                f"helper program `{self.address}` closed its input", "run it by hand to see why"
            ) from error

    def _read(self, size: int) -> bytes:
        assert self._proc.stdout is not None
        fd = self._proc.stdout.fileno()
        ready, _, _ = select.select([fd], [], [], self.timeout_s)
        if not ready:
            return b""
        data = os.read(fd, size)
        if not data:  # end of output: the helper exits (give it a moment to be reaped)
            try:
                self._proc.wait(timeout=self.timeout_s)
            except subprocess.TimeoutExpired:
                raise RigError(
                    f"helper program `{self.address}` closed its output",
                    "run it by hand to see why",
                ) from None
            self._check_alive()
        return data

    def _close(self) -> None:
        if self._proc.stdin:
            self._proc.stdin.close()
        if self._proc.stdout:
            self._proc.stdout.close()
        try:
            self._proc.wait(timeout=self.timeout_s)
        except subprocess.TimeoutExpired:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=self.timeout_s)
            except subprocess.TimeoutExpired:  # ignores SIGTERM
                self._proc.kill()
                self._proc.wait()
        self._stderr.close()
