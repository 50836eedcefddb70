"""A helper program's stdin/stdout as a byte channel (vendor CLIs, OLA clients, bridges)."""

from __future__ import annotations

import os
import select
import shlex
import subprocess
from collections.abc import Sequence

from calibration.errors import RigError
from drivers.transports.base import Transport


class SubprocessTransport(Transport):
    kind = "subprocess"

    def __init__(self, command: str | Sequence[str], timeout_s: float = 2.0) -> None:
        argv = shlex.split(command) if isinstance(command, str) else list(command)
        super().__init__(" ".join(argv), timeout_s)
        try:
            self._proc = subprocess.Popen(
                argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE
            )
        except FileNotFoundError as error:
            raise RigError(
                f"program {argv[0]!r} not found", "install it or give its full path in the profile"
            ) from error
        except PermissionError as error:
            raise RigError(f"program {argv[0]!r} is not executable", "chmod +x it") from error

    def _check_alive(self) -> None:
        code = self._proc.poll()
        if code is not None:
            assert self._proc.stderr is not None
            tail = self._proc.stderr.read().decode(errors="replace").strip()[-300:]
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
        except BrokenPipeError:
            self._check_alive()
            raise

    def _read(self, size: int) -> bytes:
        assert self._proc.stdout is not None
        fd = self._proc.stdout.fileno()
        ready, _, _ = select.select([fd], [], [], self.timeout_s)
        if not ready:
            return b""
        data = os.read(fd, size)
        if not data:
            self._check_alive()
        return data

    def _close(self) -> None:
        if self._proc.stdin:
            self._proc.stdin.close()
        try:
            self._proc.wait(timeout=self.timeout_s)
        except subprocess.TimeoutExpired:
            self._proc.terminate()
            self._proc.wait(timeout=self.timeout_s)
