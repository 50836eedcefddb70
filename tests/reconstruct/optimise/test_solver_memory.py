"""The solver keeps freed blocks in the heap while it runs and gives them back afterwards."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from reconstruct.optimise.solver import _glibc

# Run in a fresh interpreter: the allocator's thresholds are process-wide, and a long test
# process (thousands of mappings, libraries that tune malloc) is not the state being tested.
MEASURE = """
import json, resource
import numpy as np
from reconstruct.optimise.solver import keep_freed_memory

def faults_of_a_fresh_block(n=8_000_000):
    block = np.ones(n)
    del block
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    block = np.ones(n)
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
    del block
    return faults

outside = faults_of_a_fresh_block()
with keep_freed_memory():
    inside = faults_of_a_fresh_block()
after = faults_of_a_fresh_block()
print(json.dumps([outside, inside, after]))
"""


@pytest.mark.skipif(_glibc() is None, reason="glibc's mallopt only")
def test_freed_blocks_are_reused_inside_and_returned_after() -> None:
    """Minor page faults of allocating and touching a fresh 64 MB block after freeing one."""
    run = subprocess.run(
        [sys.executable, "-c", MEASURE], capture_output=True, text=True, check=True
    )
    outside, inside, after = json.loads(run.stdout)
    assert outside > 100  # 64 MB faulted in again (4 KB pages, or fewer huge pages)
    assert inside < outside / 10
    assert after > outside / 2  # the defaults are back
