"""The batch's summary: a rich table for the terminal and a CSV with one row per session."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rich.table import Table
from rich.text import Text

from core.files import atomic_output
from core.text import printable
from rig.batch.task import Outcome

FIGURES = (
    "vertices",
    "observed_vertices",
    "light_offset_cm",
    "cost_total",
    "cost_rendering",
    "cost_spectral",
    "spectral_rmse",
    "accuracy_mm",
    "recon_seconds",
    "skipped_frames",
)
COLUMNS = ("session", "status", "seconds", *FIGURES, "error")
# The table's columns (the CSV has them all) and their short headers.
TABLE = (
    "session",
    "status",
    "seconds",
    "vertices",
    "light_offset_cm",
    "cost_total",
    "spectral_rmse",
    "accuracy_mm",
    "skipped_frames",
)
HEADERS = {
    "seconds": "time s",
    "light_offset_cm": "light offset cm",
    "cost_total": "cost",
    "spectral_rmse": "spectral RMSE",
    "accuracy_mm": "accuracy mm",
    "skipped_frames": "frames left out",
}
STYLE = {"done": "green", "incomplete": "yellow", "skipped": "cyan", "failed": "bold red"}


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list):
        return " ".join(f"{v:g}" for v in value)
    return str(value)


def rows(outcomes: Sequence[Outcome]) -> list[dict[str, str]]:
    """One mapping per session over :data:`COLUMNS`, values as printed."""
    return [
        {
            "session": o.session,
            "status": o.status,
            "seconds": f"{o.seconds:.1f}",
            **{k: _cell(o.figures.get(k)) for k in FIGURES},
            "error": o.error,
        }
        for o in outcomes
    ]


def _short(session: str) -> str:
    """The session as the user likely typed it: relative to the working folder when inside."""
    path = Path(session)
    return str(path.relative_to(Path.cwd())) if path.is_relative_to(Path.cwd()) else session


def table(outcomes: Sequence[Outcome]) -> Table:
    """The terminal's view, narrow enough for 80 columns: figures no session has are left
    out, errors are printed below it. Cells are plain text (never read as markup)."""
    data = rows(outcomes)
    for row in data:
        row["session"] = _short(row["session"])
    shown = [c for c in TABLE if c in ("session", "status") or any(r[c] for r in data)]
    out = Table(title=f"rig batch: {len(outcomes)} session(s)")
    for column in shown:
        left = column in ("session", "status", "light_offset_cm")
        out.add_column(
            HEADERS.get(column, column), justify="left" if left else "right", overflow="fold"
        )
    for row in data:
        out.add_row(
            *(Text(printable(row[c]), style=STYLE.get(row[c], "") if c == "status" else "")
              for c in shown)
        )
    return out


def write_csv(path: Path, outcomes: Sequence[Outcome]) -> Path:
    """Every column for every session, for a spreadsheet."""
    with atomic_output(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows(outcomes))
    return path
