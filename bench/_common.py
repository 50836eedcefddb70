"""What every benchmark shares: machine description, peak RSS, a rich table that is also kept
as markdown (for bench/README.md), results JSON, and running one measured case in a fresh
interpreter (so its peak RSS is its own: ``ru_maxrss`` never goes down within a process)."""

from __future__ import annotations

import datetime as dt
import json
import os
import platform
import resource
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import scipy
from rich.console import Console
from rich.table import Table

from calibration.colour_difference import DEFAULT_ILLUMINANTS
from calibration.grid import DEFAULT_GRID
from core.machine import usable_cores

REPO = Path(__file__).resolve().parent.parent
DEFAULT_OUT = REPO / "bench" / "results"
WORKER_TAG = "BENCH-RESULT "  # a worker's last stdout line: this tag + JSON


def cpu_model() -> str:
    """The CPU's marketing name (``/proc/cpuinfo`` on Linux, else what platform knows)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def total_ram_gb() -> float:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1024**3
    except (ValueError, OSError, AttributeError):
        return float("nan")


def machine_info() -> dict[str, Any]:
    """Enough to tell whether two result tables are comparable."""
    return {
        "date_utc": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "cpu_model": cpu_model(),
        "cpu_count": os.cpu_count(),
        "cpus_usable": usable_cores(),
        "ram_gb": round(total_ram_gb(), 1),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "load_avg_1min": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
    }


def machine_line(info: dict[str, Any]) -> str:
    return (
        f"{info['cpu_model']}, {info['cpus_usable']}/{info['cpu_count']} CPUs usable, "
        f"{info['ram_gb']} GB RAM, Python {info['python']}, numpy {info['numpy']}, "
        f"scipy {info['scipy']}, load {info['load_avg_1min']} at start, {info['date_utc']}"
    )


def make_console() -> Console:
    """A console; when piped, wide enough for the result tables (rich would use 80 columns)."""
    return Console() if sys.stdout.isatty() else Console(width=220)


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far (MB); Linux reports KiB, macOS bytes."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 1024 if sys.platform != "darwin" else peak / 1024**2


def cache_temporary(path: Path) -> Path:
    """The name a cache file is written under before its rename: one per process, since runs
    sharing a cache may write the same file at once."""
    return path.with_name(f"{path.stem}.{os.getpid()}.tmp{path.suffix}")


class ResultTable:
    """Rows shown as a rich table and kept as markdown for the README."""

    def __init__(self, title: str, columns: Sequence[str]) -> None:
        self.title = title
        self.columns = list(columns)
        self.rows: list[list[str]] = []

    def add(self, *cells: object) -> None:
        if len(cells) != len(self.columns):
            raise ValueError(f"{self.title}: {len(cells)} cells for {len(self.columns)} columns")
        self.rows.append([c if isinstance(c, str) else fmt(c) for c in cells])

    def rich(self) -> Table:
        table = Table(title=self.title)
        for c in self.columns:
            table.add_column(c, justify="left" if c == self.columns[0] else "right")
        for row in self.rows:
            table.add_row(*row)
        return table

    def markdown(self) -> str:
        lines = [
            f"**{self.title}**",
            "",
            "| " + " | ".join(self.columns) + " |",
            "|" + "|".join(["---"] * len(self.columns)) + "|",
        ]
        lines += ["| " + " | ".join(r) + " |" for r in self.rows]
        return "\n".join(lines)

    def as_dict(self) -> dict[str, Any]:
        return {"title": self.title, "columns": self.columns, "rows": self.rows}


def fmt(value: object, digits: int = 4) -> str:
    """Numbers to short strings (``-`` for missing)."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int | np.integer):
        return f"{int(value):,}"
    if isinstance(value, float | np.floating):
        v = float(value)
        if not np.isfinite(v):
            return "-" if np.isnan(v) else str(v)
        return f"{v:.{digits}g}"
    return str(value)


COLOUR_ILLUMINANTS = DEFAULT_ILLUMINANTS  # the illuminants every evaluation reports
COLOUR_COLUMNS = [
    f"ΔE00 {n} {what}" for n in COLOUR_ILLUMINANTS
    for what in ("vertex mean / median / p90", "patch mean / max")
]  # fmt: skip


def colour_cells(colour: Sequence[dict[str, Any]]) -> list[str]:
    """The :data:`COLOUR_COLUMNS` cells of an evaluation's ``colour`` list
    (:meth:`calibration.colour_difference.ColourReport.as_dict` per illuminant)."""
    by_name = {c["illuminant"]: c for c in colour}
    cells = []
    for name in COLOUR_ILLUMINANTS:
        c = by_name.get(name)
        if c is None:
            cells += ["-", "-"]
            continue
        v = c["per_vertex"]
        cells.append(f"{v['mean']:.2f} / {v['median']:.2f} / {v['p90']:.2f}")
        if c["patch_mean"] is None:
            cells.append("-")
            continue
        cell = f"{c['patch_mean']:.2f} / {c['patch_max']:.2f}"
        measured, listed = c["patches_measured"], len(c["patches"])
        cells.append(cell if measured == listed else f"{cell} ({measured} of {listed})")
    return cells


def information_floor(session: Path) -> dict[str, Any]:
    """The information floor of a sim or external session's illuminations and camera
    (:func:`reconstruct.outputs.evaluate.information_floor` on its ground truth), with its
    ``brightness`` (:func:`brightness`)."""
    from calibration.basis import default_basis
    from calibration.estimation import noise_free_estimate
    from core.session import Session
    from reconstruct.outputs.evaluate import information_floor as floor
    from reconstruct.run.pipeline import session_responses

    responses = session_responses(Session.open(session))
    truth_path = session / "ground_truth" / "reflectance.npy"
    truth = np.load(truth_path)
    estimate = noise_free_estimate(truth, responses, default_basis())
    return {**floor(truth_path, responses), "brightness": brightness(estimate, truth, responses)}


CAMERA_BAND = 0.1
"""Wavelengths where the summed response of all illuminations reaches this share of its peak
are the ones the camera sees; the rest is filled in by the estimator's prior."""


def brightness(
    estimate: np.ndarray,
    truth: np.ndarray,
    responses: np.ndarray,
    wavelengths: np.ndarray = DEFAULT_GRID.wavelengths,
) -> dict[str, float]:
    """Median over vertices of mean(estimate) / mean(truth) per vertex (P, N_λ): over all
    wavelengths (``all``), inside the band the camera sees under the illuminations
    (``in_band``) and outside it (``out_of_band``), and the band's ends in nm.
    A bias in band is radiometric; one only out of band is the estimator's prior."""
    seen = np.sum(np.asarray(responses, dtype=float), axis=(0, 1))
    band = seen >= CAMERA_BAND * seen.max()
    est, ref = np.asarray(estimate, dtype=float), np.asarray(truth, dtype=float)
    ok = np.all(np.isfinite(est), axis=1)
    est, ref = est[ok], ref[ok]

    def ratio(columns: np.ndarray) -> float:
        if not columns.any():
            return float("nan")
        return float(np.median(est[:, columns].mean(axis=1) / ref[:, columns].mean(axis=1)))

    inside = np.flatnonzero(band)
    return {
        "all": ratio(np.ones_like(band)),
        "in_band": ratio(band),
        "out_of_band": ratio(~band),
        "band_first_nm": float(wavelengths[inside[0]]),
        "band_last_nm": float(wavelengths[inside[-1]]),
    }


def report(
    name: str,
    out_dir: Path,
    tables: Sequence[ResultTable],
    payload: dict[str, Any],
    info: dict[str, Any],
    console: Console | None = None,
    notes: Sequence[str] = (),
) -> Path:
    """Print the tables; write ``<name>.json`` (tables + payload + machine) and ``<name>.md``."""
    console = console or Console()
    out_dir.mkdir(parents=True, exist_ok=True)
    for t in tables:
        console.print(t.rich())
    console.print(f"[dim]machine: {machine_line(info)}[/]")
    for n in notes:
        console.print(f"[dim]{n}[/]")
    data = {"machine": info, "tables": [t.as_dict() for t in tables], **payload}
    path = out_dir / f"{name}.json"
    path.write_text(json.dumps(data, indent=2, default=_json_default))
    md = [f"Machine: {machine_line(info)}", ""]
    for t in tables:
        md += [t.markdown(), ""]
    md += [f"- {n}" for n in notes]
    (out_dir / f"{name}.md").write_text("\n".join(md).rstrip() + "\n")
    console.print(f"results: {path}")
    return path


def _json_default(value: object) -> object:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def emit_worker_result(result: dict[str, Any]) -> None:
    """A worker's answer to :func:`run_worker`, with its own peak RSS."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    result = {**result, "peak_rss_mb": peak_rss_mb(), "cpu_s": usage.ru_utime + usage.ru_stime}
    sys.stdout.write("\n" + WORKER_TAG + json.dumps(result, default=_json_default) + "\n")
    sys.stdout.flush()


def blas_env(threads: int | None) -> dict[str, str]:
    """The environment with the BLAS/OpenMP thread count pinned (None: library default)."""
    env = dict(os.environ)
    if threads is not None:
        for key in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env[key] = str(threads)
    return env


def run_worker(
    module: str,
    args: Sequence[str],
    timeout_s: float | None = None,
    blas_threads: int | None = None,
) -> dict[str, Any]:
    """Run ``python -m module --worker ARGS`` in a fresh interpreter and return its result
    (stderr passes through so its progress shows). A failed worker raises with its output;
    one past ``timeout_s`` is killed (``subprocess.TimeoutExpired``)."""
    cmd = [sys.executable, "-m", module, "--worker", *args]
    proc = subprocess.run(
        cmd,
        cwd=REPO,
        stdout=subprocess.PIPE,
        text=True,
        timeout=timeout_s,
        check=False,
        env=blas_env(blas_threads),
    )
    for line in reversed(proc.stdout.splitlines()):
        if line.startswith(WORKER_TAG):
            result: dict[str, Any] = json.loads(line[len(WORKER_TAG) :])
            return result
    raise RuntimeError(
        f"worker {' '.join(cmd)} exited {proc.returncode} without a result:\n{proc.stdout[-4000:]}"
    )
