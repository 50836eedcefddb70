"""The optimiser's iterations as progress bars: one bar per stage (``light 0``, ``joint 1``,
…) filled up to the stage's iteration cap, with the current total cost. Each iteration's cost
terms are logged at INFO (``reconstruct.optimise``) so they land in ``recon/log.txt`` and show
on the terminal with ``-v``, instead of one printed line per iteration at every verbosity."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from types import TracebackType
from typing import Any, TypeVar

from rich.console import Console
from rich.progress import (
    TaskID,
)

from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.solver import IterationRecord
from reconstruct.stages.progress import new_progress

log = logging.getLogger("reconstruct.optimise")
T = TypeVar("T")

HEADER = (
    "stage     it   rendering    spectral  photometric   geometric        total      step"
    "  λ        CG  time"
)


def iteration_row(stage: str, rec: IterationRecord) -> str:
    """One iteration as a fixed-width row under :data:`HEADER`."""
    t = rec.terms
    mark = "" if rec.accepted else " (rejected)"
    return (
        f"{stage:8s} {rec.iteration:3d}  {t['rendering']:10.4e}  {t['spectral']:10.3e}  "
        f"{t['photometric']:10.3e}  {t['geometric']:10.3e}  {t['total']:11.5e}  "
        f"{rec.step_norm:8.2e}  {rec.lam:7.1e}  {rec.cg_iterations:3d}  "
        f"{rec.seconds:5.2f}s{mark}"
    )


class IterationProgress:
    """Progress callback for :func:`reconstruct.run.pipeline.run_reconstruction`; use it as a
    context manager around the run. ``caps`` maps a stage kind (``light``, ``joint``) to its
    iteration limit; ``show=False`` (unattended workers) only logs."""

    def __init__(
        self, caps: Mapping[str, int], console: Console | None = None, show: bool = True
    ) -> None:
        self.caps = dict(caps)
        self.progress = new_progress(console) if show else None
        self.tasks: dict[str, TaskID] = {}
        self.current: str | None = None
        self.completed = 0
        self.header = False

    @classmethod
    def for_config(
        cls, config: Mapping[str, Any] | None, console: Console | None = None, show: bool = True
    ) -> IterationProgress:
        """Caps from the reconstruct config's ``optimise`` section."""
        settings = OptimiseSettings.from_mapping((config or {}).get("optimise"))
        caps = {
            "light": settings.light_iterations,
            "coarse": settings.joint_iterations,
            "joint": settings.joint_iterations,
        }
        return cls(caps, console, show)

    def __enter__(self) -> IterationProgress:
        if self.progress is not None:
            self.progress.start()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self.progress is not None:
            self.progress.stop()

    def __call__(self, stage: str, rec: IterationRecord) -> None:
        if not self.header:
            log.info(HEADER)
            self.header = True
        log.info(iteration_row(stage, rec))
        if self.progress is None:
            return
        if stage not in self.tasks:
            if self.current is not None:  # the previous stage stopped (converged or capped)
                self.progress.update(self.tasks[self.current], total=self.completed)
            total = self.caps.get(stage.split()[0])
            self.tasks[stage] = self.progress.add_task(f"optimise: {stage}", total=total, note="")
        self.current, self.completed = stage, rec.iteration
        self.progress.update(
            self.tasks[stage], completed=rec.iteration, note=f"cost {rec.terms['total']:.4e}"
        )
