"""The first half of ``rig reconstruct``: decode -> poses -> initial mesh -> visibility ->
subdivide, each resumable, outputs in ``SESSION/recon/``; returns what the optimiser needs.

Projector sessions (Gray-code frames in the manifest) build the initial mesh from structured
light (:mod:`reconstruct.initial_mesh.procam`, into ``recon/procam/``) instead of the visual
hull, hand the
optimiser the projector's light position per view, and keep their structured-light frames out
of the spectral observations."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from rich import get_console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from core.config import from_mapping
from core.errors import RigError
from core.labels import is_structured
from core.session import RECON_DIR, Session
from reconstruct.frames import decode
from reconstruct.frames.decode import DecodeConfig, DecodedFrame, DecodeIndex
from reconstruct.geometry import subdivide, visibility
from reconstruct.geometry.subdivide import SubdivideConfig
from reconstruct.geometry.visibility import Visibility, VisibilityConfig
from reconstruct.initial_mesh import stage as initial_mesh
from reconstruct.initial_mesh.dense.bright_pixels import GLOSSY_BRIGHT_RATIO
from reconstruct.initial_mesh.dense.mirror import GLOSSY_MIRROR_DEG, MIN_VIEWS
from reconstruct.initial_mesh.dense.poisson import read_mesh
from reconstruct.initial_mesh.procam import (
    LIGHTS,
    ProcamConfig,
    has_gray_code,
    procam_initial_mesh,
    read_light_positions,
)
from reconstruct.initial_mesh.stage import MeshConfig
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.poses import stage as poses
from reconstruct.poses.board_sfm import session_board
from reconstruct.poses.config import PosesConfig
from reconstruct.poses.output import PoseSet, PoseSummary
from reconstruct.poses.output import load as load_poses
from reconstruct.stages.resolution import (
    MAX_SIDE,
    ResolutionConfig,
    StageLevels,
    choose,
    mm_per_px,
)
from reconstruct.stages.resumable import attach_log_file

log = logging.getLogger("reconstruct")


@dataclass(frozen=True)
class FrontConfig:
    """Configuration of the five stages (each a section of the same name); ``procam`` replaces
    ``mesh`` on projector sessions; ``resolution`` chooses each stage's pyramid level."""

    decode: DecodeConfig = field(default_factory=DecodeConfig)
    poses: PosesConfig = field(default_factory=PosesConfig)
    mesh: MeshConfig = field(default_factory=MeshConfig)
    visibility: VisibilityConfig = field(default_factory=VisibilityConfig)
    subdivide: SubdivideConfig = field(default_factory=SubdivideConfig)
    procam: ProcamConfig = field(default_factory=ProcamConfig)
    resolution: ResolutionConfig = field(default_factory=ResolutionConfig)

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any] | None, where: str = "config") -> FrontConfig:
        """From the config's front sections; every error names ``where`` and the key."""
        return from_mapping(cls, data, where)


@dataclass
class FrontResult:
    """Everything the optimiser needs, as paths and loaded objects.

    ``frames`` holds only the spectral observations: on projector sessions the Gray-code and
    reference frames are left out. ``light_positions`` (view -> world position, metres) comes
    from the projector's recovered placements; ``initial_light_positions`` is the same in the
    order of ``sorted(poses)`` when every posed view has one, and ``light_mode_hint`` is then
    ``"free"`` (one near point light per view); both are None on bulb sessions. ``levels``:
    each stage's pyramid level (the optimiser samples ``frames`` ``levels.optimise_step``
    levels down).
    """

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
    levels: StageLevels
    structured_light: bool = False
    light_positions: dict[int, np.ndarray] = field(default_factory=dict)
    initial_light_positions: np.ndarray | None = None
    light_mode_hint: str | None = None

    def frame_path(self, view: int, illumination: str) -> Path:
        """The decoded float16 image of a (view, illumination)."""
        return self.decoded_dir / self.frames[(view, illumination)].image

    @property
    def scale_is_metric(self) -> bool:
        return self.pose_summary.scale == "metric"


def _lights(
    pose_map: Mapping[int, Pose], procam_dir: Path
) -> tuple[dict[int, np.ndarray], np.ndarray | None]:
    """Projector light position per view, and as an array over ``sorted(pose_map)`` when
    every posed view has one."""
    lights = read_light_positions(procam_dir)
    missing = sorted(set(pose_map) - set(lights))
    if missing:
        log.warning("views %s have no projector light position (placement not recovered)",
                    missing)
        return lights, None
    return lights, np.stack([lights[v] for v in sorted(pose_map)])


def _mesh_config(conf: MeshConfig, session: Session, summary: PoseSummary) -> MeshConfig:
    """Poses in the board's frame (board poses, or known poses the board's corners agree
    with): the silhouettes are cut against the board's known print (it is no dark
    background) and the hull kept above it."""
    in_board_frame = summary.source.startswith("board") or summary.extra.get("board_frame")
    if conf.board is not None or not in_board_frame:
        return conf
    spec = session_board(session.info)
    return conf if spec is None else replace(conf, board=spec.to_dict())


def stage_levels(conf: FrontConfig, decoded_dir: Path, posed: PoseSet) -> StageLevels:
    """Each stage's pyramid level from the decoded frames and the footprint of the poses."""
    level = min(f.level for f in DecodeIndex.load(decoded_dir).frames)
    metric = posed.summary.scale == "metric" and len(posed.poses) >= 2
    footprint = mm_per_px(posed.intrinsics, posed.poses) if metric else None
    levels = choose(conf.resolution, level, conf.subdivide.target_px, footprint,
                    conf.mesh.patchmatch.scale)
    log.info("resolution %s: decoded frames at level %d, PatchMatch at %d, optimiser at %d, "
             "target edge %.3g px%s", conf.resolution.detail, levels.decode, levels.patchmatch,
             levels.optimise, levels.edge_px,
             "" if levels.edge_mm is None else f" ({levels.edge_mm:.3g} mm)")
    return levels


def _patchmatch_scale(conf: MeshConfig, levels: StageLevels) -> MeshConfig:
    """PatchMatch at the chosen level unless the config names its scale."""
    if conf.patchmatch.scale is not None:
        return conf
    return replace(conf, patchmatch=replace(conf.patchmatch, scale=levels.patchmatch_scale))


def _highlight_passes(conf: MeshConfig, glossy: bool, views: int) -> MeshConfig:
    """Highlights left out of fusion, by their normals and by their brightness, on an object
    declared glossy and seen from enough views, unless the config names the angle or ratio."""
    pm = conf.patchmatch
    leave_out = glossy and views >= MIN_VIEWS
    if glossy and not leave_out and pm.mirror_deg is None:
        log.info("glossy object seen from %d views: highlights stay in fusion (below %d views "
                 "leaving them out costs more than they do; mesh.patchmatch.mirror_deg forces it)",
                 views, MIN_VIEWS)
    angle = GLOSSY_MIRROR_DEG if leave_out else 0.0
    ratio = GLOSSY_BRIGHT_RATIO if leave_out else 0.0
    return replace(conf, patchmatch=replace(
        pm,
        mirror_deg=angle if pm.mirror_deg is None else pm.mirror_deg,
        bright_ratio=ratio if pm.bright_ratio is None else pm.bright_ratio,
    ))


def run_front(
    session: Session | Path,
    conf: FrontConfig | Mapping[str, Any] | None = None,
    initial_mesh_file: Path | None = None,
    glossy: bool = False,
) -> FrontResult:
    """Run (or resume) the five stages on a session (opened by the caller, or its folder).
    The session is opened and the poses are loaded once here and handed to each stage.
    ``glossy``: the optimiser models gloss (``optimise.gloss`` or ``highlights``), so the
    initial mesh leaves highlights out too."""
    conf = conf if isinstance(conf, FrontConfig) else FrontConfig.from_mapping(conf or {})
    session = Session.of(session)
    session_dir = session.root
    projector = has_gray_code(session)
    recon = session_dir / RECON_DIR
    handler = attach_log_file(recon)
    dirs = {
        n: recon / n for n in ("decoded", "poses", "mesh", "procam", "visibility", "subdivide")
    }
    try:
        with Progress(
            TextColumn("[bold]{task.description}"), BarColumn(), TimeElapsedColumn(),
            transient=True, disable=not get_console().is_terminal,  # no blank line in a log
        ) as progress:
            task = progress.add_task("reconstruct: decode", total=5)
            # Gray codes keep every pixel: their finest stripes are a pixel or two wide
            max_side = 0 if projector else MAX_SIDE[conf.resolution.detail]
            decode.run(conf.decode, session, dirs["decoded"], max_side)
            progress.update(task, advance=1, description="reconstruct: poses")
            poses.run(conf.poses, session, dirs["decoded"], dirs["poses"])
            posed = load_poses(dirs["poses"])
            levels = stage_levels(conf, dirs["decoded"], posed)
            progress.update(task, advance=1, description="reconstruct: initial mesh")
            if projector and initial_mesh_file is None:
                mesh0 = procam_initial_mesh(
                    session, posed.poses, posed.intrinsics, conf.procam, dirs["procam"],
                    decoded_dir=dirs["decoded"],
                )
            else:
                mesh_conf = _mesh_config(conf.mesh, session, posed.summary)
                mesh0 = initial_mesh.run(
                    _highlight_passes(_patchmatch_scale(mesh_conf, levels), glossy,
                                      len(posed.poses)),
                    dirs["decoded"],
                    dirs["poses"], dirs["mesh"], initial_mesh_file, posed,
                    # the paper's start where the profile names no mount: the lamp at the lens
                    np.asarray(session.info.light_offset_m or (0.0, 0.0, 0.0), dtype=float),
                )
            progress.update(task, advance=1, description="reconstruct: visibility")
            vis0 = visibility.run(
                conf.visibility, mesh0, dirs["poses"], dirs["visibility"], posed
            )
            progress.update(task, advance=1, description="reconstruct: subdivide")
            edge_mm = conf.resolution.edge_mm
            fine = subdivide.run(
                conf.subdivide, mesh0, vis0, dirs["poses"], dirs["subdivide"], conf.visibility,
                posed, None if edge_mm is None else edge_mm / 1e3,
            )
            progress.update(task, advance=1)
    finally:
        log.removeHandler(handler)
        handler.close()
    intrinsics, pose_map, summary = posed
    index = DecodeIndex.load(dirs["decoded"])
    frames = {
        (f.view, f.illumination): f
        for f in index.frames
        if f.view in pose_map and not (projector and is_structured(f.illumination))
    }
    if projector and not frames:
        raise RigError(
            f"{session_dir} has only structured-light frames: nothing to measure reflectance "
            "from", "capture the projector's uniform colours too (the plan's illuminations)",
        )
    vis_path = dirs["subdivide"] / visibility.FILE
    result = FrontResult(
        recon, dirs["decoded"], intrinsics, pose_map, summary, frames, mesh0, fine,
        read_mesh(fine), vis_path, Visibility.load(vis_path), dict(index.skipped), levels,
        projector,
    )
    if projector and (dirs["procam"] / LIGHTS).is_file():
        result.light_positions, result.initial_light_positions = _lights(pose_map, dirs["procam"])
        if result.initial_light_positions is not None:
            result.light_mode_hint = "free"
    return result
