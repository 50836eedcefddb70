"""Putting a new set of ``recon/`` outputs in place without ever mixing old and new files.

The exporter writes into ``recon/.export-new/``; :func:`publish` then removes the completion
marker ``recon/outputs.json``, moves the previous outputs to ``recon/.export-old/``, renames
the new ones in and writes the marker last, listing them. A kill while staging leaves the old
set and its marker untouched; a kill during the swap leaves no marker and only new files (the
next run exports again). Readers trust the outputs only when the marker lists them.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from core.files import fsync_dir, write_bytes_atomically

STAGING = ".export-new"
OLD = ".export-old"
MARKER = "outputs.json"
# Outputs written before the marker existed (an older version's recon folder).
LEGACY = ("mesh.ply", "reflectance.npz", "report.json", "*.png")
# `rig evaluate`'s files in recon/: they describe the set they were computed on, so a new
# set replaces them too (run `rig evaluate` again); nothing else of the person's is touched.
EVALUATION = (
    "evaluation.json",
    "spectral_rmse_per_vertex.npy",
    "spectral_error_map.png",
    "spectral_error_hist.png",
)


def staging_dir(recon_dir: Path) -> Path:
    """A fresh, empty staging folder (what an interrupted export left there is discarded)."""
    staging = recon_dir / STAGING
    shutil.rmtree(staging, ignore_errors=True)
    shutil.rmtree(recon_dir / OLD, ignore_errors=True)
    staging.mkdir(parents=True)
    return staging


def published(recon_dir: Path) -> list[str] | None:
    """The output files of the last complete export, or None when there is none."""
    try:
        data = json.loads((recon_dir / MARKER).read_text())
        return [str(name) for name in data["files"]]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _current(recon_dir: Path) -> set[str]:
    """The files the new set replaces: the marker's list (or, without a marker, the legacy
    patterns) and the evaluation of that set."""
    listed = published(recon_dir)
    names = set(listed or [])
    for pattern in (*(LEGACY if listed is None else ()), *EVALUATION):
        names.update(p.name for p in recon_dir.glob(pattern) if p.is_file())
    return names


def publish(recon_dir: Path, staging: Path) -> list[Path]:
    """Swap the staged files in for the previous outputs; returns their final paths."""
    new = sorted(p.name for p in staging.iterdir() if p.is_file())
    replaced = _current(recon_dir) - {MARKER}  # read while the marker still lists the old set
    (recon_dir / MARKER).unlink(missing_ok=True)
    fsync_dir(recon_dir)
    old_dir = recon_dir / OLD
    old_dir.mkdir(exist_ok=True)
    for name in replaced:
        if (recon_dir / name).is_file():
            (recon_dir / name).replace(old_dir / name)
    fsync_dir(recon_dir)
    for name in new:
        (staging / name).replace(recon_dir / name)
    fsync_dir(recon_dir)
    marker = json.dumps({"files": new}, indent=2) + "\n"
    write_bytes_atomically(recon_dir / MARKER, marker.encode())
    shutil.rmtree(old_dir, ignore_errors=True)
    shutil.rmtree(staging, ignore_errors=True)
    return [recon_dir / name for name in new]
