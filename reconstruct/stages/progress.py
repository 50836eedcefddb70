"""Progress bars in the project's layout, and a transient bar for loops over views."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import TypeVar

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
)

T = TypeVar("T")


def new_progress(console: Console | None = None, transient: bool = False) -> Progress:
    """The project's bar layout: description, bar, done/total, elapsed time, a note."""
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.fields[note]}", markup=False),  # notes name sessions and files
        console=console,
        transient=transient,
    )


def track(items: Sequence[T], description: str) -> Iterator[T]:
    """Iterate with a transient bar on stderr: for loops over views that take seconds each
    (plane-sweep stereo, visibility ray casting), gone from the terminal once done. Not on a
    log file or pipe, where a transient bar would only leave a blank line."""
    console = Console(stderr=True)
    if not console.is_terminal:
        yield from items
        return
    with new_progress(console, transient=True) as bar:
        task = bar.add_task(description, total=len(items), note="")
        for item in items:
            yield item
            bar.advance(task)
