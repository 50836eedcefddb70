"""Progress for a log or a pipe, where rich's live bars show nothing until the end: a plain
line at each step and one every ``every_s`` seconds while the step lasts, naming the
reconstruction stage in progress (from ``recon/status.json``) when there is one."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from types import TracebackType

from rich.console import Console

from core.errors import RigError
from reconstruct.run.status import read_status


class ProgressLines:
    """Use as a context manager around the steps; :meth:`step` names the current one.
    ``recon_dir``: the reconstruction whose stage the periodic lines report."""

    def __init__(
        self, console: Console, every_s: float = 30.0, recon_dir: Path | None = None
    ) -> None:
        self.console = console
        self.every_s = every_s
        self.recon_dir = recon_dir
        self.description = ""
        self.started = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, name="progress-lines", daemon=True)

    def __enter__(self) -> ProgressLines:
        self._thread.start()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._stop.set()
        self._thread.join()

    def step(self, description: str) -> None:
        self.description = description
        self._line(description)

    def _beat(self) -> None:
        while not self._stop.wait(self.every_s):
            stage = self._stage()
            self._line(self.description + (f" (stage: {stage})" if stage else ""))

    def _stage(self) -> str | None:
        if self.recon_dir is None:
            return None
        try:
            status = read_status(self.recon_dir)
        except RigError:  # being rewritten: the next beat reads it
            return None
        if status is None or status.get("status") != "running":
            return None
        return str(status.get("stage"))

    def _line(self, text: str) -> None:
        elapsed = int(time.monotonic() - self.started)
        self.console.print(
            f"[{elapsed // 60:d}:{elapsed % 60:02d}] {text}", markup=False, highlight=False
        )
