"""Resumable, timed reconstruction stages (modelled on hloc).

Each stage is ``run(conf, inputs, out_dir) -> Path``. :func:`run_stage` wraps the work: it
skips when ``out_dir`` holds a stamp whose hash matches the stage's configuration and its
input files (path, size, mtime), and otherwise runs it, writes the stamp last (so an
interrupted stage re-runs) and records the wall time in ``recon/timings.json``: within
:func:`timed_run` (one reconstruction) in memory, the file written once at its end. Hashing
size+mtime rather than content keeps resuming cheap; frame contents are checked against the
manifest's sha256 by the decode stage.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import RigError
from core.files import write_bytes_atomically
from core.fserrors import fs_error
from reconstruct.stages.memory import peak_rss_mb, reset_peak_rss

log = logging.getLogger("reconstruct")

STAMP = ".stamp.json"
TIMINGS = "timings.json"
LOG_FILE = "log.txt"


@dataclass(frozen=True)
class StageRun:
    """What happened to one stage: its name, output folder, whether it was skipped, seconds."""

    name: str
    out_dir: Path
    skipped: bool
    seconds: float


def _files(paths: Iterable[Path]) -> list[Path]:
    out: list[Path] = []
    for path in paths:
        if path.is_dir():
            out.extend(p for p in sorted(path.rglob("*")) if p.is_file() and p.name != STAMP)
        else:
            out.append(path)
    return out


def stage_hash(conf: Mapping[str, Any], inputs: Iterable[Path]) -> str:
    """Hash of the configuration and of each input file's path, size and mtime. The path is
    resolved first: `sessions/vase/...` and `/data/sessions/vase/...` are one file."""
    digest = hashlib.sha256(json.dumps(conf, sort_keys=True, default=str).encode())
    for path in _files(inputs):
        path = path.resolve()
        stat = path.stat() if path.exists() else None
        key = f"{path}|{stat.st_size}|{stat.st_mtime_ns}" if stat else f"{path}|missing"
        digest.update(key.encode())
    return digest.hexdigest()


def is_done(out_dir: Path, digest: str) -> bool:
    stamp = out_dir / STAMP
    if not stamp.is_file():
        return False
    try:
        return bool(json.loads(stamp.read_text())["hash"] == digest)
    except (json.JSONDecodeError, KeyError):
        return False


class Timings:
    """``recon/timings.json``: each stage's wall time and peak resident memory
    (:mod:`reconstruct.stages.memory`), earlier runs' entries kept for stages this run did not
    reach."""

    def __init__(self, recon_dir: Path) -> None:
        self.path = recon_dir / TIMINGS
        self.data: dict[str, Any] = {}
        if self.path.is_file():
            try:
                self.data = json.loads(self.path.read_text())
            except json.JSONDecodeError:
                self.data = {}

    def record(
        self, name: str, seconds: float, skipped: bool, peak_rss_mb: float | None = None
    ) -> None:
        self.data[name] = {
            "seconds": round(seconds, 3),
            "skipped": skipped,
            "peak_rss_mb": None if peak_rss_mb is None else round(peak_rss_mb, 1),
            "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }

    def peaks(self, leave_out: Iterable[str] = ()) -> dict[str, float | None]:
        """Peak resident memory (MB) of each stage with an entry, but those in ``leave_out``."""
        skip = set(leave_out)
        return {
            name: entry.get("peak_rss_mb")
            for name, entry in self.data.items()
            if isinstance(entry, dict) and name not in skip
        }

    def write(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomically(self.path, json.dumps(self.data, indent=2).encode())


_RUN_TIMINGS: ContextVar[Timings | None] = ContextVar("run_timings", default=None)


@contextmanager
def timed_run(recon_dir: Path) -> Iterator[Timings]:
    """Collect the timings of every stage run inside the block; write them once at its end
    (also when it fails, so a resumed run's report still sees what finished)."""
    timings = Timings(recon_dir)
    token = _RUN_TIMINGS.set(timings)
    try:
        yield timings
    except BaseException:
        _RUN_TIMINGS.reset(token)
        with contextlib.suppress(RigError):  # a full disk: the error raised is what matters
            timings.write()
        raise
    _RUN_TIMINGS.reset(token)
    timings.write()


def record_timing(
    recon_dir: Path, name: str, seconds: float, skipped: bool, peak_rss_mb: float | None = None
) -> None:
    """Add one stage's wall time to the run's timings (inside :func:`timed_run`), else straight
    to ``recon/timings.json`` (a stage run alone)."""
    timings = _RUN_TIMINGS.get()
    if timings is not None:
        timings.record(name, seconds, skipped, peak_rss_mb)
        return
    alone = Timings(recon_dir)
    alone.record(name, seconds, skipped, peak_rss_mb)
    alone.write()


def run_stage(
    name: str,
    conf: Mapping[str, Any],
    inputs: Iterable[Path],
    out_dir: Path,
    work: Callable[[], object],
    recon_dir: Path | None = None,
) -> StageRun:
    """Run ``work`` unless ``out_dir`` is stamped with the same conf + inputs hash."""
    recon_dir = recon_dir or out_dir.parent
    digest = stage_hash(conf, inputs)
    start = time.perf_counter()
    if is_done(out_dir, digest):
        log.info("%s: up to date, skipped (%s)", name, out_dir)
        record_timing(recon_dir, name, 0.0, True)
        return StageRun(name, out_dir, True, 0.0)
    log.info("%s: running -> %s", name, out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / STAMP).unlink(missing_ok=True)
    reset_peak_rss()
    try:
        work()
    except OSError as error:  # a full or read-only disk: one line naming the file, not a bug
        raise fs_error(error, out_dir) from error
    seconds = time.perf_counter() - start
    write_bytes_atomically(out_dir / STAMP, json.dumps({"hash": digest, "stage": name}).encode())
    record_timing(recon_dir, name, seconds, False, peak_rss_mb())
    log.info("%s: done in %.2f s", name, seconds)
    return StageRun(name, out_dir, False, seconds)


@contextmanager
def quiet_colmap() -> Iterator[None]:
    """Silence COLMAP's INFO lines (they would drown the progress display) for a block."""
    import pycolmap

    level = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 1
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = level


def attach_log_file(recon_dir: Path) -> logging.Handler:
    """Send the ``reconstruct`` logger to ``recon/log.txt`` (appending across runs). When an
    enclosing block already logs there (:mod:`reconstruct.run.logfile`) a no-op handler is returned,
    so no line is written twice."""
    recon_dir.mkdir(parents=True, exist_ok=True)
    path = os.path.abspath(recon_dir / LOG_FILE)
    if any(getattr(h, "baseFilename", None) == path for h in log.handlers):
        return logging.NullHandler()
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    log.addHandler(handler)
    if log.level == logging.NOTSET or log.level > logging.INFO:
        log.setLevel(logging.INFO)
    return handler
