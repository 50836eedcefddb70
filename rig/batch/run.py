"""Dispatch: every session one task on the cluster, collected as they finish under a progress
bar. A task that dies with its worker (killed, out of memory) is reported like a failed
session; the others go on."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from distributed import as_completed
from rich.console import Console

from core.text import printable
from reconstruct.stages.progress import new_progress
from rig.batch.cluster import open_client
from rig.batch.task import Outcome, reconstruct_session


def run_batch(
    sessions: Sequence[Path],
    config: Mapping[str, Any],
    force: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    verbosity: int = 0,
    console: Console | None = None,
) -> list[Outcome]:
    """Reconstruct ``sessions`` (absolute paths the workers can read); outcomes in order."""
    names = [str(s) for s in sessions]
    outcomes: dict[str, Outcome] = {}
    with open_client(workers, scheduler) as client, new_progress(console) as bar:
        task = bar.add_task("rig batch", total=len(names), note="")
        futures = {
            client.submit(
                reconstruct_session,
                name,
                dict(config),
                force,
                verbosity,
                key=f"reconstruct-{i}-{Path(name).name}",
                pure=False,
            ): name
            for i, name in enumerate(names)
        }
        for future in as_completed(futures):
            name = futures[future]
            try:
                outcome = future.result()
            except Exception as error:  # the worker died under the task
                outcome = Outcome(name, "failed", error=f"{type(error).__name__}: {error}")
            outcomes[name] = outcome
            failed = sum(o.status == "failed" for o in outcomes.values())
            bar.update(
                task,
                advance=1,
                note=printable(f"{Path(name).name}: {outcome.status}")
                + (f" ({failed} failed)" if failed else ""),
            )
    return [outcomes[n] for n in names]
