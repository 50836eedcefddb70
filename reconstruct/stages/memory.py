"""Peak resident memory per stage, for ``recon/timings.json`` and ``report.json``.

Linux keeps a process's high-water mark of resident memory (``VmHWM``); writing ``5`` to
``/proc/self/clear_refs`` resets it, so resetting before a stage and reading after it gives
that stage's own peak instead of the run's so far. Where that is not possible (another OS, an
older kernel) the reading is the process's peak so far (``getrusage``), which is still an
upper bound."""

from __future__ import annotations

import resource
import sys
from pathlib import Path

_STATUS = Path("/proc/self/status")
_CLEAR_REFS = Path("/proc/self/clear_refs")


def reset_peak_rss() -> bool:
    """Start a new high-water mark; False where the kernel does not allow it."""
    try:
        _CLEAR_REFS.write_text("5")
    except OSError:
        return False
    return True


def peak_rss_mb() -> float:
    """The high-water mark of resident memory since the last reset, in MB (10⁶ bytes)."""
    try:
        for line in _STATUS.read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024 / 1e6
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux, bytes on macOS
    return peak / 1e6 if sys.platform == "darwin" else peak * 1024 / 1e6
