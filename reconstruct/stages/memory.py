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

import psutil

# The joint solve's resident memory besides the frames it samples, in GB (10⁹ bytes): a fixed
# part and a part per million (vertex, frame) pairs the visibility allows. Fitted to
# bench.real_size's runs and kept on the high side, since a warning too late loses the run.
SOLVE_BASE_GB = 1.0
SOLVE_GB_PER_MILLION_PAIRS = 0.5

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


def solve_memory_gb(pairs: int, frame_bytes: int) -> float:
    """The joint solve's expected peak resident memory in GB: the frames it holds
    (``frame_bytes``) and the visible (vertex, frame) ``pairs`` it may observe.

    >>> round(solve_memory_gb(10_000_000, 600_000_000), 1)
    6.6
    """
    return SOLVE_BASE_GB + SOLVE_GB_PER_MILLION_PAIRS * pairs / 1e6 + frame_bytes / 1e9


def memory_within_reach_gb() -> float:
    """What this process holds now plus what the system can still give it, in GB."""
    return (psutil.Process().memory_info().rss + psutil.virtual_memory().available) / 1e9
