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
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import trimesh
from scipy.spatial import cKDTree

from core.config import bounded, from_mapping
from core.errors import RigError
from core.files import write_bytes_atomically
from reconstruct.frames.decode import INDEX, DecodeIndex, load_frame
from reconstruct.initial_mesh.dense.board_silhouette import board_silhouette
from reconstruct.initial_mesh.dense.bright_pixels import without_bright
from reconstruct.initial_mesh.dense.mirror import without_near_mirror
from reconstruct.initial_mesh.dense.patchmatch import (
    DenseResult,
    PatchMatchConfig,
    fuse,
    patchmatch_points,
    working_images,
)
from reconstruct.initial_mesh.dense.poisson import poisson_mesh, read_mesh
from reconstruct.initial_mesh.dense.silhouette import silhouette
from reconstruct.initial_mesh.dense.stereo import (
    StereoConfig,
    carve_hull_points,
    hull_stereo_points,
    thin,
)
from reconstruct.initial_mesh.dense.visual_hull import silhouette_votes, visual_hull_points
from reconstruct.initial_mesh.repair import RepairConfig, repair
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.raycast import RayCaster
from reconstruct.poses.board import BoardSpec
from reconstruct.poses.output import POINTS, PoseSet
from reconstruct.poses.output import load as load_poses
from reconstruct.stages.resumable import run_stage

log = logging.getLogger("reconstruct.initial_mesh.stage")
# fewer fused stereo points than this cannot support a Poisson surface (pycolmap's trimmer
# crashes on an empty cloud); the hull is the better mesh then
MIN_STEREO_POINTS = 500

MESH = "initial.ply"
SUMMARY = "initial.json"


@dataclass(frozen=True)
class MeshConfig:
    """``voxels``: visual-hull resolution on the longest side of the object's box;
    ``poisson_trim``: density below which Poisson's surface is trimmed; ``mask_dilate_px``:
    slack added to each silhouette against pose error (raise it to the reprojection error
    of poorly posed views; unset: 2 px for ``patchmatch``, whose search the hull only bounds
    and must not cut off at the rim, 0 for the methods whose surface is the hull's);
    ``carve_votes``: how many views must see a voxel as background
    to carve it (unset: 3 for ``patchmatch``, whose search the hull only bounds, which forgives
    a cast shadow as dark as the background cutting a limb's outline in two views; 2 for the
    methods whose surface is the hull's, which a looser hull would cost accuracy); ``method``:
    ``visual_hull`` alone, ``hull_stereo`` which adds hull-guided NCC plane-sweep stereo
    for what silhouettes miss (concavities), or ``patchmatch``: per-view PatchMatch depth and
    normal maps searched within the hull's bounds, fused, and meshed without hull points
    (``patchmatch`` holds its settings); ``fill_unseen_from_hull``: with ``patchmatch``, add
    the hull's points on surface no camera could match (an underside, a slot) so Poisson
    does not flare there; off by default because the hull under an object is a flat box
    that costs accuracy where stereo alone leaves a smaller hole; ``board``: the printed
    board under the object (a ``BoardSpec`` or its profile mapping; poses must be in the
    board's frame), whose print replaces the dark background; ``floor_margin_m``: the hull
    is carved above this height over the board."""

    def __post_init__(self) -> None:
        self.board_spec()  # a malformed board fails here, naming the key

    def hull_votes(self, hull_is_surface: bool | None = None) -> int:
        """``carve_votes``, or its default: 2 where the hull is the surface (by default for
        every method but ``patchmatch``), 3 where it only bounds PatchMatch's search."""
        if self.carve_votes is not None:
            return self.carve_votes
        surface = self.method != "patchmatch" if hull_is_surface is None else hull_is_surface
        return 2 if surface else 3

    def board_spec(self) -> BoardSpec | None:
        if self.board is None or isinstance(self.board, BoardSpec):
            return self.board
        return BoardSpec.from_dict(dict(self.board), source="mesh.board")

    method: Literal["hull_stereo", "patchmatch", "visual_hull"] = "patchmatch"
    voxels: int = bounded(96, min=4, max=2048)
    poisson_trim: float = bounded(5.0, min=0.0, max=1000.0)
    mask_dilate_px: int | None = bounded(None, min=0, max=1000)
    carve_votes: int | None = bounded(None, min=1, max=1000)
    min_views: int = bounded(3, min=1, max=1000)
    fill_unseen_from_hull: bool = False
    # Poisson's OpenMP threads; more only pay on an idle many-core host
    num_threads: int = bounded(1, min=1, max=1024)
    stereo: StereoConfig = field(default_factory=StereoConfig)
    patchmatch: PatchMatchConfig = field(default_factory=PatchMatchConfig)
    board: Mapping[str, Any] | BoardSpec | None = None
    floor_margin_m: float = bounded(0.001, min=0.0, max=10.0)
    repair: RepairConfig = field(default_factory=RepairConfig)


def mesh_config(data: Mapping[str, Any], where: str = "config") -> MeshConfig:
    """MeshConfig from the ``mesh`` section; a ``BoardSpec`` under ``board`` is kept as its
    mapping, so the stage's stamp is the same however the board was given."""
    values = dict(data)
    if isinstance(values.get("board"), BoardSpec):
        values["board"] = values["board"].to_dict()
    return from_mapping(MeshConfig, values, where, "mesh")


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
    """Silhouette and stereo images (grey per illumination, the illuminations all views have,
    by name: (H, W, I); the brightest frame alone where they share none) of each view, one
    view's frames in memory at a time: against the known print of ``board`` (then ``intrinsics`` and
    ``poses`` are needed) or a dark background. Views whose silhouette is implausible are
    left out."""
    index = DecodeIndex.load(decoded_dir)
    by_view = defaultdict(list)
    for frame in index.frames:
        if frame.view in views:
            by_view[frame.view].append(frame)
    masks, grey = {}, {}
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * dilate_px + 1,) * 2)
    # stereo compares channel k of one view with channel k of another: the same
    # illuminations, in the same order, in every view (a skipped frame drops its
    # illumination from the stereo images of all views, not the view)
    common = sorted(set.intersection(*({f.illumination for f in fr} for fr in by_view.values()))
                    ) if by_view else []
    for view, frames in sorted(by_view.items()):
        images = [load_frame(decoded_dir, f)[0] for f in frames]
        stereo = [im for f, im in sorted(zip(frames, images, strict=True),
                                         key=lambda pair: pair[0].illumination)
                  if f.illumination in common] or [max(images, key=lambda im: float(im.mean()))]
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
        grey[view] = np.stack([im.sum(axis=2) for im in stereo], axis=-1)
    return masks, grey


def brightest(grey: np.ndarray) -> np.ndarray:
    """The brightest illumination's channel of a view's (H, W, I) stereo image."""
    return np.asarray(grey[..., int(np.argmax(grey.mean(axis=(0, 1))))])


def dense_mesh(
    decoded_dir: Path,
    poses_dir: Path,
    conf: MeshConfig,
    out_dir: Path,
    posed: PoseSet,
    light_offset: np.ndarray | None = None,
) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """The initial mesh from the decoded frames and poses, and what built it. ``light_offset``:
    the lamp's position in the camera frame (metres), which lets PatchMatch leave highlights
    out of its fusion (None: unknown, every pixel is fused)."""
    intrinsics, poses, _ = posed
    board = conf.board_spec()
    dilate_px = conf.mask_dilate_px
    if dilate_px is None:
        dilate_px = 2 if conf.method == "patchmatch" else 0
    votes = conf.hull_votes()
    masks, grey = view_masks(decoded_dir, sorted(poses), dilate_px, board, intrinsics, poses)
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
    sparse = np.load(poses_dir / POINTS)

    def hull(
        masks: dict[int, np.ndarray], votes: int
    ) -> tuple[trimesh.Trimesh, np.ndarray, np.ndarray, float]:
        points, normals, voxel = visual_hull_points(
            masks, intrinsics, poses, sparse, conf.voxels, votes, floor
        )
        mesh = poisson_mesh(points, normals, depth, conf.poisson_trim, conf.num_threads)
        return mesh, points, normals, voxel

    depth = int(np.ceil(np.log2(conf.voxels)))
    mesh, points, normals, voxel = hull(masks, votes)
    hull_surface = mesh
    info: dict[str, Any] = {"method": "visual_hull+poisson", "views": len(masks), "voxel": voxel,
                            "hull_points": len(points), "poisson_depth": depth,
                            "silhouettes": "dark_background" if board is None else "board"}
    if conf.method == "hull_stereo":
        mesh.export(out_dir / "visual_hull.ply")
        points, normals, stats = hull_stereo_points(
            mesh, points, normals, {v: brightest(g) for v, g in grey.items()}, masks, intrinsics,
            poses, voxel, conf.stereo, floor,
        )
        mesh = poisson_mesh(points, normals, depth, conf.poisson_trim, conf.num_threads)
        info |= stats | {"method": "visual_hull+plane_sweep_ncc+poisson"}
    elif conf.method == "patchmatch":
        hull_mesh = mesh
        mesh.export(out_dir / "visual_hull.ply")
        dense = patchmatch_points(
            np.asarray(mesh.vertices), np.asarray(mesh.faces), grey, masks, intrinsics, poses,
            conf.patchmatch,
        )

        def stereo_surface(fused: DenseResult) -> tuple[trimesh.Trimesh | None, dict[str, Any]]:
            """Poisson's surface of the fused points (None: too few to carry one)."""
            pm, pn = fused.points, fused.normals
            if floor is not None:  # the masks include the object's shadow on the board
                above = pm[:, 2] > floor + voxel / 2
                pm, pn = pm[above], pn[above]
            pm, pn = thin(pm, pn, voxel / 4)
            if len(pm) < MIN_STEREO_POINTS:
                return None, fused.stats | {"stereo_points": len(pm)}
            hp, hn = pm[:0], pn[:0]
            if conf.fill_unseen_from_hull:
                hp, hn = unseen_hull_points(hull_mesh, points, normals, pm, fused, poses,
                                            2 * voxel, conf.patchmatch.cost_max)
            depth = conf.patchmatch.poisson_depth
            surface = poisson_mesh(np.vstack([pm, hp]), np.vstack([pn, hn]), depth,
                                   conf.patchmatch.poisson_trim, conf.num_threads)
            moved = clip_to_hull(surface, hull_mesh, pm, voxel, masks, intrinsics, poses, votes)
            return surface, fused.stats | {
                "method": "visual_hull_bounded_patchmatch+poisson", "poisson_depth": depth,
                "hull_points_kept": len(hp), "vertices_clipped_to_hull": moved}

        surface, stereo_info = stereo_surface(dense)
        pm_conf = conf.patchmatch
        if (surface is not None and light_offset is not None
                and (pm_conf.mirror_deg or pm_conf.bright_ratio)):
            # fuse again without the pixels that saw a highlight
            maps, dropped = dense.maps, {}
            if pm_conf.mirror_deg:
                maps, dropped["near_mirror_pixels"] = without_near_mirror(
                    maps, poses, light_offset, surface, pm_conf.mirror_deg)
            if pm_conf.bright_ratio:
                views = sorted(maps)
                small, small_masks, _ = working_images(grey, masks, intrinsics, views, pm_conf)
                reach = (pm_conf.window // 2) * pm_conf.window_step
                maps, dropped["bright_pixels"] = without_bright(
                    maps, small, small_masks, poses, light_offset, surface,
                    pm_conf.bright_ratio, reach)
                del small, small_masks
            log.info("PatchMatch: leaving out %s; fusing again",
                     ", ".join(f"{n} {k.replace('_', ' ')}" for k, n in dropped.items()))
            kept_points, kept_normals, stats = fuse(maps, poses, dense.sources, pm_conf)
            second, second_info = stereo_surface(
                DenseResult(kept_points, kept_normals, stats | dropped, maps, dense.sources))
            if second is not None:
                surface, stereo_info = second, second_info
        info |= stereo_info
        if surface is not None:
            mesh = surface
        else:
            log.warning(
                "PatchMatch matched only %d points (the object shows too little texture at this "
                "image size); the initial mesh is the visual hull", stereo_info["stereo_points"],
            )
            info["method"] = "visual_hull+poisson (patchmatch matched too few points)"
            surface_votes = conf.hull_votes(hull_is_surface=True)
            if dilate_px or surface_votes != votes:
                # the hull is the surface now: carve it as the hull methods do, from the tight
                # silhouettes with their vote
                kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * dilate_px + 1,) * 2)
                mesh = hull({v: cv2.erode(m.astype(np.uint8), kernel) > 0
                             for v, m in masks.items()}, surface_votes)[0]
    if floor is not None:  # the object stands on the board: nothing of it lies below
        vertices = np.array(mesh.vertices)
        vertices[:, 2] = np.maximum(vertices[:, 2], 0.0)
        mesh = trimesh.Trimesh(vertices, mesh.faces, process=False)
    mesh, info["repair"] = repair(mesh, conf.repair, hull_surface, voxel)
    return mesh, info


def clip_to_hull(
    mesh: trimesh.Trimesh,
    hull: trimesh.Trimesh,
    stereo_points: np.ndarray,
    margin: float,
    masks: Mapping[int, np.ndarray],
    intrinsics: Mapping[int, Intrinsics],
    poses: Mapping[int, Pose],
    votes: int,
) -> int:
    """Move the vertices that Poisson guessed over a hole (no stereo point within
    ``margin``) and that lie outside the visual hull (outside ``votes`` views' silhouettes)
    onto the closest point of the ``hull`` mesh, in place; returns how many moved.

    Over a hole Poisson's smooth guess can flare centimetres out; the object lies inside its
    hull, so there the hull's surface is the nearest place the vertex can be right. Vertices
    stereo measured stay: silhouettes err too (a dark flank read as background in a few
    views), and clipping measured surface to them costs accuracy."""
    vertices = np.array(mesh.vertices)
    guessed = np.ones(len(vertices), bool)
    if len(stereo_points):
        near, _ = cKDTree(stereo_points).query(vertices, distance_upper_bound=margin)
        guessed = ~np.isfinite(near)
    idx = np.flatnonzero(guessed)
    outside, _ = silhouette_votes(vertices[idx], dict(masks), dict(intrinsics), dict(poses))
    idx = idx[outside >= votes]
    if len(idx):
        vertices[idx] = trimesh.proximity.closest_point(hull, vertices[idx])[0]
        mesh.vertices = vertices
    return len(idx)


def unseen_hull_points(
    hull: trimesh.Trimesh,
    hull_points: np.ndarray,
    hull_normals: np.ndarray,
    stereo_points: np.ndarray,
    dense: DenseResult,
    poses: Mapping[int, Pose],
    margin: float,
    cost_max: float,
    min_views: int = 3,
) -> tuple[np.ndarray, np.ndarray]:
    """The visual hull's points on surface no camera could match: fewer than ``min_views``
    views face them unoccluded (the underside of an overhang, a slot), no stereo point lies
    within ``margin``, and no view's depth map puts the surface behind them (then the hull
    bridges a concavity that view looked into). There the hull's surface is the best guess;
    Poisson's closure over such a region flares by centimetres. Holes that many views see
    (the untextured interior of a painted patch) are left to Poisson and the joint
    optimisation's shading term: the hull there is a voxel or two off, which is worse."""
    if not len(hull_points):
        return hull_points, hull_normals
    free = np.ones(len(hull_points), bool)
    if len(stereo_points):
        near, _ = cKDTree(stereo_points).query(hull_points, distance_upper_bound=margin)
        free &= ~np.isfinite(near)
    caster = RayCaster(np.asarray(hull.vertices), np.asarray(hull.faces))
    seen = np.zeros(len(hull_points), np.int32)
    for pose in poses.values():
        to_cam = pose.center - hull_points
        facing = np.einsum("ij,ij->i", hull_normals, to_cam) > 0.3 * np.linalg.norm(to_cam, axis=1)
        idx = np.flatnonzero(free & facing)
        seen[idx] += ~caster.occluded(hull_points[idx], pose.center, 1e-4, hull_normals[idx])
    free &= seen < min_views
    depths = {v: vd.depth(cost_max) for v, vd in dense.maps.items()}
    intrinsics = {v: vd.intrinsics for v, vd in dense.maps.items()}
    free &= carve_hull_points(hull_points, depths, intrinsics, dict(poses), margin)
    return hull_points[free], hull_normals[free]


def _initial(
    decoded_dir: Path,
    poses_dir: Path,
    conf: MeshConfig,
    out_dir: Path,
    user: Path | None,
    posed: PoseSet | None,
    light_offset: np.ndarray | None,
) -> None:
    info: dict[str, Any]
    if user is not None:
        mesh, repaired = repair(
            load_user_mesh(user), conf.repair,
            fix=f"give {user} as one closed, consistently wound surface, or leave "
            "--initial-mesh out to build the mesh from the images",
        )
        info = {"method": "given", "source": str(user), "repair": repaired}
    else:
        posed = posed or load_poses(poses_dir)
        mesh, info = dense_mesh(decoded_dir, poses_dir, conf, out_dir, posed, light_offset)
    if info["repair"]["actions"]:
        log.warning("initial mesh repaired: %s", "; ".join(info["repair"]["actions"]))
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
    posed: PoseSet | None = None,
    light_offset: np.ndarray | None = None,
) -> Path:
    """Write ``out_dir/initial.ply`` (resumable); returns its path. ``posed``: the poses
    stage's output when the caller has loaded it; ``light_offset``: the lamp in the camera
    frame (metres; None: unknown), as :func:`dense_mesh` takes it."""
    conf = conf if isinstance(conf, MeshConfig) else mesh_config(conf)
    inputs = [decoded_dir / INDEX, poses_dir / "images.txt", poses_dir / "cameras.txt"]
    if initial_mesh is not None:
        inputs.append(Path(initial_mesh))
    if out_dir.exists() and not (out_dir / ".stamp.json").exists():
        shutil.rmtree(out_dir)
    run_stage(
        "initial_mesh",
        asdict(conf) | {"given": str(initial_mesh),
                        "light_offset": None if light_offset is None else list(light_offset)},
        inputs, out_dir,
        lambda: _initial(decoded_dir, poses_dir, conf, out_dir, initial_mesh, posed,
                         light_offset),
    )
    return out_dir / MESH
