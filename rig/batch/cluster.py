"""The Dask cluster a batch runs on: an existing scheduler, or a local one sized to the machine.

A local cluster uses worker processes with one thread each (a reconstruction is one process's
work; NumPy's own threads are pinned to one by Dask's nanny), as many as there are cores and
memory for, each limited to its share of the machine's memory. It listens on 127.0.0.1 only and
has no dashboard."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import psutil
from distributed import Client, LocalCluster

from core.errors import RigError
from core.machine import usable_cores

# What one reconstruction of a demo-sized session (20 views, 60k faces) needs, with margin.
WORKER_MEMORY = 4 * 2**30


def local_size(workers: int | None) -> tuple[int, int]:
    """Number of workers and memory limit per worker (bytes) on this machine."""
    memory = int(psutil.virtual_memory().total)
    cores = usable_cores()
    if workers is None:
        workers = max(1, min(cores, memory // WORKER_MEMORY))
    return workers, memory // workers


def check_single_threaded(client: Client, scheduler: str) -> None:
    """A reconstruction redirects its process's stderr and logging into the session's log, so
    two sessions in one worker process would write into each other's logs."""
    workers = client.scheduler_info().get("workers", {})
    shared = sorted(addr for addr, info in workers.items() if int(info.get("nthreads", 1)) > 1)
    if shared:
        raise RigError(
            f"the Dask workers at {scheduler} run several threads each ({shared[0]} and "
            f"{len(shared) - 1} more): sessions would share a process and mix their logs",
            "start the workers with `dask worker ADDRESS --nthreads 1` (one process per session)",
        )


@contextmanager
def open_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Client]:
    """A client of ``scheduler`` (``tcp://host:port``), else of a new local cluster."""
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as error:
            raise RigError(
                f"cannot reach the Dask scheduler at {scheduler}: {error}",
                "start it (`dask scheduler`) or check --scheduler's address",
            ) from error
        with client:
            check_single_threaded(client, scheduler)
            yield client
        return
    n, memory = local_size(workers)
    with (
        LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            memory_limit=memory,
            host="127.0.0.1",
            dashboard_address=None,
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client
