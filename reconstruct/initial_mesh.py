"""Initial mesh stage: a user-supplied mesh, or a CPU dense path (visual hull + Poisson).

``--initial-mesh FILE`` takes any mesh trimesh reads, in the world frame of the poses (e.g.
from OpenMVS or Metashape run on the same images with the same poses). Without one, the
silhouettes of the decoded frames are carved into a visual hull whose oriented boundary
points go through Poisson reconstruction (``pycolmap.poisson_meshing``, CPU). Outputs in
``recon/mesh/``: ``initial.ply``, ``initial.json`` and the silhouettes in ``masks/``.

With ``mesh.board`` (the printed board the object stands on, poses in its frame) silhouettes
compare each view with the known print instead of a dark background, the hull is carved
above the board only (z > ``floor_margin_m``) and nothing of the mesh reaches below it.
"""

from __future__ import annotations

import json
import logging
import shutil
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import trimesh

from calibration.errors import RigError
from reconstruct import poses as poses_stage
from reconstruct.board import BoardSpec
from reconstruct.camera import Intrinsics, Pose
from reconstruct.config_check import check_types
from reconstruct.decode import INDEX, DecodeIndex, load_frame
from reconstruct.dense.board_silhouette import board_silhouette
from reconstruct.dense.patchmatch import PatchMatchConfig, patchmatch_points
from reconstruct.dense.poisson import poisson_mesh, read_mesh
from reconstruct.dense.silhouette import silhouette
from reconstruct.dense.stereo import StereoConfig, hull_stereo_points, thin
from reconstruct.dense.visual_hull import visual_hull_points
from reconstruct.session import write_bytes_atomically
from reconstruct.stages import run_stage

log = logging.getLogger("reconstruct.initial_mesh")

MESH = "initial.ply"
METHODS = ("hull_stereo", "patchmatch", "visual_hull")
SUMMARY = "initial.json"


@dataclass(frozen=True)
class MeshConfig:
    """``voxels``: visual-hull resolution on the longest side of the object's box;
    ``poisson_trim``: density below which Poisson's surface is trimmed; ``mask_dilate_px``:
    slack added to each silhouette against pose error (raise it to the reprojection error
    of poorly posed views); ``carve_votes``: how many views must see a voxel as background
    to carve it (2 forgives a shadow touching one view's outline); ``method``:
    ``visual_hull`` alone, ``hull_stereo`` which adds hull-guided NCC plane-sweep stereo
    for what silhouettes miss (concavities), or ``patchmatch``: per-view PatchMatch depth and
    normal maps searched within the hull's bounds, fused, and meshed without hull points
    (``patchmatch`` holds its settings); ``board``: the printed board under the object
    (a ``BoardSpec`` or its profile mapping; poses must be in the board's frame), whose
    print replaces the dark background; ``floor_margin_m``: the hull is carved above this
    height over the board."""

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise RigError(
                f"mesh.method {self.method!r} is unknown", f"use one of {', '.join(METHODS)}"
            )
        self.board_spec()  # a malformed board fails here, naming the key

    def board_spec(self) -> BoardSpec | None:
        if self.board is None or isinstance(self.board, BoardSpec):
            return self.board
        return BoardSpec.from_dict(dict(self.board), source="mesh.board")

    method: str = "hull_stereo"  # one of METHODS
    voxels: int = 96
    poisson_trim: float = 5.0
    mask_dilate_px: int = 0
    carve_votes: int = 2
    min_views: int = 3
    num_threads: int = 1  # Poisson's OpenMP threads; more only pay on an idle many-core host
    stereo: StereoConfig = field(default_factory=StereoConfig)
    patchmatch: PatchMatchConfig = field(default_factory=PatchMatchConfig)
    board: BoardSpec | Mapping[str, Any] | None = None
    floor_margin_m: float = 0.001


def mesh_config(data: Mapping[str, Any]) -> MeshConfig:
    """MeshConfig from a mapping whose ``stereo`` and ``patchmatch`` sections may themselves be
    mappings (checked key by key like the top-level sections)."""
    values = dict(data)
    for key, kind in (("stereo", StereoConfig), ("patchmatch", PatchMatchConfig)):
        if isinstance(values.get(key), Mapping):
            values[key] = _nested_section(values[key], kind, f"config mesh.{key}")
    if isinstance(values.get("board"), BoardSpec):
        values["board"] = values["board"].to_dict()
    return MeshConfig(**values)


def _nested_section(value: Mapping[str, Any], kind: type[Any], where: str) -> Any:
    known = {f.name for f in fields(kind)}
    bad = set(value) - known
    if bad:
        raise RigError(
            f"unknown key(s) in {where}: {', '.join(sorted(bad))}",
            f"use {', '.join(sorted(known))}",
        )
    check_types(value, kind(), where)
    return kind(**value)


def load_user_mesh(path: Path) -> trimesh.Trimesh:
    """A mesh file trimesh reads; scenes are merged into one mesh."""
    if not Path(path).is_file():
        raise RigError(f"initial mesh {path} does not exist", "give an existing mesh file")
    try:
        mesh = read_mesh(path, process=True)
    except RigError:
        raise
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise RigError(
            f"initial mesh {path} cannot be read ({exc})", "give a PLY, OBJ, STL, OFF or GLB mesh"
        ) from exc
    if len(mesh.faces) == 0:
        raise RigError(f"initial mesh {path} has no triangles", "give a triangle mesh")
    return mesh


def view_masks(
    decoded_dir: Path,
    views: list[int],
    dilate_px: int,
    board: BoardSpec | None = None,
    intrinsics: Mapping[int, Intrinsics] | None = None,
    poses: Mapping[int, Pose] | None = None,
) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """Silhouette and stereo images (grey per illumination, brightest first: (H, W, I)) of
    each view, one view's frames in
    memory at a time: against the known print of ``board`` (then ``intrinsics`` and
    ``poses`` are needed) or a dark background. Views whose silhouette is implausible are
    left out."""
    index = DecodeIndex.load(decoded_dir)
    by_view = defaultdict(list)
    for frame in index.frames:
        if frame.view in views:
            by_view[frame.view].append(frame)
    masks, grey = {}, {}
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * dilate_px + 1,) * 2)
    for view, frames in sorted(by_view.items()):
        images = [load_frame(decoded_dir, f)[0] for f in frames]
        if board is None or intrinsics is None or poses is None:
            mask = silhouette(images)
        else:
            intr = intrinsics[view]
            if images[0].shape[:2] != (intr.height, intr.width):
                raise RigError(
                    f"view {view}: decoded frames are {images[0].shape[1]}x"
                    f"{images[0].shape[0]} px but its camera is {intr.width}x{intr.height}",
                    "re-run the poses stage on the same decoded frames",
                )
            mask = board_silhouette(images, board, intr, poses[view])
        fraction = float(mask.mean())
        if not 1e-4 < fraction < 0.95:
            log.warning("view %d: silhouette covers %.1f%% of the image, not used", view,
                        100 * fraction)
            continue
        masks[view] = cv2.dilate(mask.astype(np.uint8), kernel) > 0 if dilate_px else mask
        bright_first = sorted(images, key=lambda im: -float(im.mean()))
        grey[view] = np.stack([im.sum(axis=2) for im in bright_first], axis=-1)
    return masks, grey


def dense_mesh(
    decoded_dir: Path, poses_dir: Path, conf: MeshConfig, out_dir: Path
) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    intrinsics, poses, _ = poses_stage.load(poses_dir)
    board = conf.board_spec()
    masks, grey = view_masks(
        decoded_dir, sorted(poses), conf.mask_dilate_px, board, intrinsics, poses
    )
    floor = None if board is None else conf.floor_margin_m
    if len(masks) < conf.min_views:
        raise RigError(
            f"only {len(masks)} views have a usable silhouette; the visual hull needs "
            f"{conf.min_views}",
            "keep the whole object on the board in view" if board is not None
            else "photograph the object against a dark background, or give --initial-mesh",
        )
    (out_dir / "masks").mkdir(exist_ok=True)
    for view, mask in masks.items():
        cv2.imwrite(str(out_dir / "masks" / f"view_{view:04d}.png"), mask.astype(np.uint8) * 255)
    sparse = np.load(poses_dir / poses_stage.POINTS)
    points, normals, voxel = visual_hull_points(
        masks, intrinsics, poses, sparse, conf.voxels, conf.carve_votes, floor
    )
    depth = int(np.ceil(np.log2(conf.voxels)))
    mesh = poisson_mesh(points, normals, depth, conf.poisson_trim, conf.num_threads)
    info: dict[str, Any] = {"method": "visual_hull+poisson", "views": len(masks), "voxel": voxel,
                            "hull_points": len(points), "poisson_depth": depth,
                            "silhouettes": "dark_background" if board is None else "board"}
    if conf.method == "hull_stereo":
        mesh.export(out_dir / "visual_hull.ply")
        points, normals, stats = hull_stereo_points(
            mesh, points, normals, {v: g[..., 0] for v, g in grey.items()}, masks, intrinsics,
            poses, voxel, conf.stereo, floor,
        )
        mesh = poisson_mesh(points, normals, depth, conf.poisson_trim, conf.num_threads)
        info |= stats | {"method": "visual_hull+plane_sweep_ncc+poisson"}
    elif conf.method == "patchmatch":
        mesh.export(out_dir / "visual_hull.ply")
        points, normals, stats = patchmatch_points(
            np.asarray(mesh.vertices), np.asarray(mesh.faces), grey, masks, intrinsics, poses,
            conf.patchmatch,
        )
        if floor is not None:  # the masks include the object's shadow on the board
            above = points[:, 2] > floor + voxel / 2
            points, normals = points[above], normals[above]
        points, normals = thin(points, normals, voxel / 4)
        depth = conf.patchmatch.poisson_depth
        mesh = poisson_mesh(points, normals, depth, conf.patchmatch.poisson_trim,
                            conf.num_threads)
        info |= stats | {"method": "visual_hull_bounded_patchmatch+poisson",
                         "poisson_depth": depth}
    if floor is not None:  # the object stands on the board: nothing of it lies below
        vertices = np.array(mesh.vertices)
        vertices[:, 2] = np.maximum(vertices[:, 2], 0.0)
        mesh = trimesh.Trimesh(vertices, mesh.faces, process=False)
    return mesh, info


def _initial(
    decoded_dir: Path, poses_dir: Path, conf: MeshConfig, out_dir: Path, user: Path | None
) -> None:
    info: dict[str, Any]
    if user is not None:
        mesh, info = load_user_mesh(user), {"method": "given", "source": str(user)}
    else:
        mesh, info = dense_mesh(decoded_dir, poses_dir, conf, out_dir)
    mesh.export(out_dir / MESH)
    info |= {"vertices": len(mesh.vertices), "faces": len(mesh.faces),
             "watertight": bool(mesh.is_watertight)}
    write_bytes_atomically(out_dir / SUMMARY, json.dumps(info, indent=1).encode())
    log.info("initial mesh (%s): %d vertices, %d faces", info["method"], info["vertices"],
             info["faces"])


def run(
    conf: MeshConfig | Mapping[str, Any],
    decoded_dir: Path,
    poses_dir: Path,
    out_dir: Path,
    initial_mesh: Path | None = None,
) -> Path:
    """Write ``out_dir/initial.ply`` (resumable); returns its path."""
    conf = conf if isinstance(conf, MeshConfig) else mesh_config(conf)
    inputs = [decoded_dir / INDEX, poses_dir / "images.txt", poses_dir / "cameras.txt"]
    if initial_mesh is not None:
        inputs.append(Path(initial_mesh))
    if out_dir.exists() and not (out_dir / ".stamp.json").exists():
        shutil.rmtree(out_dir)
    run_stage(
        "initial_mesh", asdict(conf) | {"given": str(initial_mesh)}, inputs, out_dir,
        lambda: _initial(decoded_dir, poses_dir, conf, out_dir, initial_mesh),
    )
    return out_dir / MESH
