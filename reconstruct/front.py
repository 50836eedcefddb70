"""The first half of ``rig reconstruct``: decode -> poses -> initial mesh -> visibility ->
subdivide, each resumable, outputs in ``SESSION/recon/``; returns what the optimiser needs."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import trimesh
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from calibration.errors import RigError
from reconstruct import decode, initial_mesh, poses, subdivide, visibility
from reconstruct.camera import Intrinsics, Pose
from reconstruct.decode import DecodeConfig, DecodedFrame, DecodeIndex
from reconstruct.dense.poisson import read_mesh
from reconstruct.initial_mesh import MeshConfig, mesh_config
from reconstruct.poses import PosesConfig, PoseSummary
from reconstruct.session import RECON_DIR
from reconstruct.stages import attach_log_file
from reconstruct.subdivide import SubdivideConfig
from reconstruct.visibility import Visibility, VisibilityConfig

log = logging.getLogger("reconstruct")


@dataclass(frozen=True)
class FrontConfig:
    """Configuration of the five stages (each a section of the same name)."""

    decode: DecodeConfig = field(default_factory=DecodeConfig)
    poses: PosesConfig = field(default_factory=PosesConfig)
    mesh: MeshConfig = field(default_factory=MeshConfig)
    visibility: VisibilityConfig = field(default_factory=VisibilityConfig)
    subdivide: SubdivideConfig = field(default_factory=SubdivideConfig)

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> FrontConfig:
        sections = {f.name: f for f in fields(cls)}
        unknown = set(data) - set(sections)
        if unknown:
            raise RigError(
                f"unknown reconstruction config section(s): {', '.join(sorted(unknown))}",
                f"use {', '.join(sections)}",
            )
        built: dict[str, Any] = {}
        for name, value in data.items():
            kind = type(getattr(cls(), name))
            if isinstance(value, kind):
                built[name] = value
                continue
            known = {f.name for f in fields(kind)}
            bad = set(value or {}) - known
            if bad:
                raise RigError(
                    f"unknown key(s) in config section {name}: {', '.join(sorted(bad))}",
                    f"use {', '.join(sorted(known))}",
                )
            built[name] = mesh_config(value or {}) if kind is MeshConfig else kind(**(value or {}))
        return cls(**built)


@dataclass
class FrontResult:
    """Everything the optimiser needs, as paths and loaded objects."""

    recon_dir: Path
    decoded_dir: Path
    intrinsics: dict[int, Intrinsics]
    poses: dict[int, Pose]
    pose_summary: PoseSummary
    frames: dict[tuple[int, str], DecodedFrame]  # (view, illumination) -> decoded frame
    initial_mesh_path: Path
    mesh_path: Path
    mesh: trimesh.Trimesh
    visibility_path: Path
    visibility: Visibility
    skipped_frames: dict[str, str]  # frame path -> why it was left out

    def frame_path(self, view: int, illumination: str) -> Path:
        """The decoded float16 image of a (view, illumination)."""
        return self.decoded_dir / self.frames[(view, illumination)].image

    def saturation_path(self, view: int, illumination: str) -> Path:
        return self.decoded_dir / self.frames[(view, illumination)].saturated

    @property
    def scale_is_metric(self) -> bool:
        return self.pose_summary.scale == "metric"


def run_front(
    session_dir: Path,
    conf: FrontConfig | Mapping[str, Any] | None = None,
    initial_mesh_file: Path | None = None,
) -> FrontResult:
    """Run (or resume) the five stages on a session directory."""
    session_dir = Path(session_dir)
    conf = conf if isinstance(conf, FrontConfig) else FrontConfig.from_mapping(conf or {})
    recon = session_dir / RECON_DIR
    handler = attach_log_file(recon)
    dirs = {n: recon / n for n in ("decoded", "poses", "mesh", "visibility", "subdivide")}
    try:
        with Progress(
            TextColumn("[bold]{task.description}"), BarColumn(), TimeElapsedColumn(),
            transient=True,
        ) as progress:
            task = progress.add_task("reconstruct: decode", total=5)
            decode.run(conf.decode, session_dir, dirs["decoded"])
            progress.update(task, advance=1, description="reconstruct: poses")
            poses.run(conf.poses, session_dir, dirs["decoded"], dirs["poses"])
            progress.update(task, advance=1, description="reconstruct: initial mesh")
            mesh0 = initial_mesh.run(
                conf.mesh, dirs["decoded"], dirs["poses"], dirs["mesh"], initial_mesh_file
            )
            progress.update(task, advance=1, description="reconstruct: visibility")
            vis0 = visibility.run(conf.visibility, mesh0, dirs["poses"], dirs["visibility"])
            progress.update(task, advance=1, description="reconstruct: subdivide")
            fine = subdivide.run(
                conf.subdivide, mesh0, vis0, dirs["poses"], dirs["subdivide"], conf.visibility
            )
            progress.update(task, advance=1)
    finally:
        log.removeHandler(handler)
        handler.close()
    intrinsics, pose_map, summary = poses.load(dirs["poses"])
    index = DecodeIndex.load(dirs["decoded"])
    frames = {(f.view, f.illumination): f for f in index.frames if f.view in pose_map}
    vis_path = dirs["subdivide"] / visibility.FILE
    return FrontResult(
        recon, dirs["decoded"], intrinsics, pose_map, summary, frames, mesh0, fine,
        read_mesh(fine), vis_path, Visibility.load(vis_path), dict(index.skipped),
    )
