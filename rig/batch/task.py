"""One session's reconstruction as a Dask task, and the figures read back from its outputs.

The task never raises: a broken session becomes a ``failed`` outcome with its one-line error,
so the other sessions of the batch go on. Everything the pipeline would print goes to the
session's ``recon/log.txt`` (the workers share one terminal)."""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from core.errors import RigError
from core.session import RECON_DIR
from reconstruct.frames.decode import list_unusable
from reconstruct.outputs import export
from reconstruct.outputs.evaluate import EVALUATION_FILE
from reconstruct.stages import publish

OUTPUTS = (export.MESH_FILE, export.REFLECTANCE_FILE, export.REPORT_FILE)


@dataclass
class Outcome:
    """What became of one session: ``done``, ``incomplete`` (done, but unusable frames were
    left out: ``error`` lists them), ``skipped`` (already reconstructed) or ``failed`` (with
    ``error``), and the figures of its report."""

    session: str
    status: str
    seconds: float = 0.0
    figures: dict[str, Any] = field(default_factory=dict)
    error: str = ""


def is_reconstructed(session: Path) -> bool:
    """A finished export lists the three outputs (a run killed mid-export has no list)."""
    listed = publish.published(session / RECON_DIR)
    return listed is not None and all(
        name in listed and (session / RECON_DIR / name).is_file() for name in OUTPUTS
    )


def report_figures(recon: Path) -> dict[str, Any]:
    """Vertices, light offset, final cost terms and run time from ``report.json``; spectral
    RMSE and accuracy from ``evaluation.json`` when `rig evaluate` has been run."""
    report = json.loads((recon / export.REPORT_FILE).read_text())
    last = next((h for h in reversed(report.get("history") or []) if h.get("accepted")), None)
    terms = last["terms"] if last else {}
    offset = (report.get("light") or {}).get("offset_m")
    figures: dict[str, Any] = {
        "vertices": report.get("vertices"),
        "observed_vertices": report.get("observed_vertices"),
        "light_offset_cm": None if offset is None else [round(v * 100, 2) for v in offset],
        "cost_total": terms.get("total"),
        "cost_rendering": terms.get("rendering"),
        "cost_spectral": terms.get("spectral"),
        "recon_seconds": round(sum((report.get("timings_s") or {}).values()), 1),
        "skipped_frames": len(report.get("skipped_frames") or {}),
    }
    evaluation = recon / EVALUATION_FILE
    if evaluation.is_file():
        ev = json.loads(evaluation.read_text())
        figures["spectral_rmse"] = ev.get("spectral_rmse")
        figures["accuracy_mm"] = None if ev.get("accuracy_m") is None else ev["accuracy_m"] * 1e3
    return figures


def reconstruct_session(
    session: str, config: Mapping[str, Any], force: bool, verbosity: int
) -> Outcome:
    """Run on a worker: reconstruct ``session`` unless it already is (or ``force``)."""
    root = Path(session)
    t0 = time.perf_counter()
    try:
        if not force and is_reconstructed(root):
            return Outcome(session, "skipped", 0.0, report_figures(root / RECON_DIR))
        from reconstruct.run.logfile import run_logged  # heavy imports stay in the workers

        rec = run_logged(root, config, None, verbosity, terminal=False)
        seconds, figures = time.perf_counter() - t0, report_figures(rec.recon_dir)
        skipped = rec.report.get("skipped_frames") or {}
        if skipped:  # as `rig reconstruct`'s exit 3: not a clean run
            message = f"frames left out: {list_unusable(skipped)}"
            return Outcome(session, "incomplete", seconds, figures, message)
        return Outcome(session, "done", seconds, figures)
    except RigError as error:
        return Outcome(session, "failed", time.perf_counter() - t0, error=str(error))
    except Exception as error:  # isolate the batch from any one session's bug
        message = f"internal error: {type(error).__name__}: {error}"
        return Outcome(session, "failed", time.perf_counter() - t0, error=message)
