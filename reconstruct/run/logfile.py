"""Where a reconstruction's chatter goes: ``SESSION/recon/log.txt``.

Our own INFO lines (the ``reconstruct`` logger) and whatever native code writes to file
descriptor 2 — COLMAP's glog lines from pycolmap, OpenMP or Embree warnings — are appended
to the session's log, so the terminal keeps only progress bars, warnings and results. glog
writes with C's ``fprintf(stderr)``, which Python's ``sys.stderr`` cannot intercept: the
descriptor itself is redirected with ``os.dup2`` for the duration of the block, while Python's
``sys.stderr`` is pointed at a duplicate of the original descriptor so rich's progress bars and
our warnings still reach the terminal.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Iterator, Mapping
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, TextIO

from rich.console import Console

from core.lock import locked
from core.manifest import MANIFEST_FILE
from core.manifest_check import check_session
from core.session import RECON_DIR, Session
from reconstruct.run.pipeline import RECONSTRUCT, Reconstruction, run_reconstruction
from reconstruct.run.progress import IterationProgress
from reconstruct.stages.resumable import LOG_FILE, attach_log_file

log = logging.getLogger("reconstruct")


@contextmanager
def _fd2_to(path: Path, terminal: bool) -> Iterator[None]:
    """Native writes to fd 2 go to ``path``; Python's ``sys.stderr`` keeps the original
    destination when ``terminal`` (interactive use), else it goes to ``path`` as well, with
    ``sys.stdout`` (a batch worker, whose terminal is shared by every session)."""
    sys.stderr.flush()
    sys.stdout.flush()
    saved = os.dup(2)
    target = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    old_err, old_out = sys.stderr, sys.stdout
    stream: TextIO
    if terminal:
        stream = os.fdopen(os.dup(saved), "w", buffering=1, encoding="utf-8", errors="replace")
    else:
        stream = open(path, "a", buffering=1, encoding="utf-8", errors="replace")
    try:
        os.dup2(target, 2)
        sys.stderr = stream
        if not terminal:
            sys.stdout = stream
        yield
    finally:
        stream.flush()
        sys.stderr, sys.stdout = old_err, old_out
        os.dup2(saved, 2)
        os.close(saved)
        os.close(target)
        stream.close()


@contextmanager
def captured_output(recon_dir: Path, native: bool = False, terminal: bool = True) -> Iterator[Path]:
    """Log this block into ``recon_dir/log.txt`` (yielded).

    ``native=True`` (``-vv``) leaves fd 2 alone so COLMAP's lines show on the terminal;
    ``terminal=False`` sends Python's own output (progress bars, iteration lines) to the log as
    well, for unattended workers.
    """
    recon_dir = Path(recon_dir)
    recon_dir.mkdir(parents=True, exist_ok=True)
    path = recon_dir / LOG_FILE
    previous = log.level
    handler = attach_log_file(recon_dir)
    with ExitStack() as stack:
        if not native or not terminal:
            stack.enter_context(_fd2_to(path, terminal))
        try:
            yield path
        finally:
            log.removeHandler(handler)
            handler.close()
            log.setLevel(previous)


def run_logged(
    session: Session | Path,
    config: Mapping[str, Any] | None = None,
    initial_mesh: Path | None = None,
    verbosity: int = 0,
    console: Console | None = None,
    terminal: bool = True,
    keep_intermediates: bool = False,
) -> Reconstruction:
    """:func:`run_reconstruction` as the CLI runs it: chatter in ``recon/log.txt``, COLMAP's
    lines too unless ``verbosity >= 2``, the optimiser's iterations as progress bars (only
    logged when ``terminal`` is false), the decoded frames deleted after a successful export
    unless ``keep_intermediates``; ``session`` opened by the caller, or its folder."""
    session = Session.of(session)  # a missing session fails before recon/ is made
    # so does a manifest that `rig session verify` or `rig capture --resume` would refuse
    check_session(session.root, session.frames, session.root / MANIFEST_FILE)
    with (
        locked(session.root, RECONSTRUCT),  # before recon/log.txt is touched
        captured_output(session.root / RECON_DIR, native=verbosity >= 2, terminal=terminal),
        IterationProgress.for_config(config, console, show=terminal) as iterations,
    ):
        return run_reconstruction(session, config, initial_mesh, iterations,
                                  keep_intermediates=keep_intermediates)
