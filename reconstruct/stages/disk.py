"""Disk used by each stage's folder under ``recon/`` (the intermediates a run leaves)."""

from __future__ import annotations

from pathlib import Path

# recon/ folders that hold a stage's working files rather than the published outputs
STAGE_FOLDERS = ("decoded", "poses", "mesh", "procam", "visibility", "subdivide", "optimise")


def folder_bytes(folder: Path) -> int:
    """Total size of the files under ``folder`` (0 when it does not exist)."""
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def stage_sizes_mb(recon_dir: Path) -> dict[str, float]:
    """Megabytes in each stage folder of ``recon_dir`` that exists."""
    return {
        name: round(folder_bytes(recon_dir / name) / 1e6, 1)
        for name in STAGE_FOLDERS
        if (recon_dir / name).is_dir()
    }
