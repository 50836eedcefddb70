"""The solver keeps freed blocks in the heap while it runs and gives them back afterwards."""

from __future__ import annotations

import resource

import numpy as np
import pytest

from reconstruct.optimise.solver import _glibc, keep_freed_memory


def _faults_of_a_fresh_block(n: int = 8_000_000) -> int:
    """Minor page faults of allocating and touching a fresh 64 MB block after freeing one."""
    block = np.ones(n)
    del block
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    block = np.ones(n)
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
    del block
    return faults


@pytest.mark.skipif(_glibc() is None, reason="glibc's mallopt only")
def test_freed_blocks_are_reused_inside_and_returned_after() -> None:
    outside = _faults_of_a_fresh_block()
    with keep_freed_memory():
        inside = _faults_of_a_fresh_block()
    after = _faults_of_a_fresh_block()
    assert outside > 100  # 64 MB faulted in again (4 KB pages, or fewer huge pages)
    assert inside < outside / 10
    assert after > outside / 2  # the defaults are back
