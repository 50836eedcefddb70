"""Projector rigs (paper Sec. 4.2, after Pro-Cam SSfM): Gray code -> dense initial mesh.

Two ways to turn decoded projector coordinates into 3-D points, chosen per session:

* ``placements`` (no projector calibration): the projector stays put while the camera takes
  several views, then moves (camera and projector moved alternately). Camera pixels of views
  lit from the same placement that decode to the same projector block see the same surface
  spot; their centroids are matched and triangulated with the camera poses. The projector's
  pose per placement is then recovered by resection (PnP) from those points, and its optical
  centre is that placement's light position.
* ``plate``: the projector rides on the camera plate at the profile's ``light_mount.offset_m``
  with the camera's orientation, so every view is its own placement and the projector is a
  second, known "camera": camera pixel and projector block are triangulated directly
  (needs the projector's focal length, e.g. throw ratio x width).

Manifest frames name their placement in ``projector_placement`` (any JSON value); without it
``auto`` picks ``plate``. Points go through a vectorised multi-view DLT, are rejected by
reprojection error, triangulation angle and cheirality, get PCA normals facing the cameras,
and are meshed by screened Poisson (``pycolmap.poisson_meshing``, CPU), trimmed to the cloud.

Outputs in ``out_dir``: ``initial.ply``, ``points.ply`` (oriented cloud), ``lights.json``
(per-view projector light position, for the optimiser's free-light mode), ``procam.json``
(counts, residuals, projector poses) and ``decoding/view_NNNN.npz``.
"""

from __future__ import annotations

import json
import logging
import tempfile
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pycolmap
import trimesh
from rich.progress import track
from scipy.linalg import rq
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from core.errors import RigError
from core.files import write_bytes_atomically
from core.manifest import FrameRecord
from core.session import Session
from reconstruct.frames.decode import INDEX, LINEAR_SUFFIXES, DecodeIndex, decode_linear, decode_raw
from reconstruct.frames.decode import load_frame as load_decoded
from reconstruct.initial_mesh.dense.poisson import read_mesh, write_oriented_ply
from reconstruct.initial_mesh.structured_light import (
    DecodeOptions,
    GrayDecoding,
    decode_gray,
    is_structured,
)
from reconstruct.model.camera import Intrinsics, Pose, project
from reconstruct.poses.sfm import rescale
from reconstruct.run.stages import run_stage

log = logging.getLogger("reconstruct.initial_mesh.procam")

MESH = "initial.ply"
POINTS = "points.ply"
LIGHTS = "lights.json"
SUMMARY = "procam.json"
PLACEMENT_KEY = "projector_placement"
MODES = ("auto", "placements", "plate")


@dataclass(frozen=True)
class ProcamConfig:
    """``mode``: auto | placements | plate; ``projector_focal_px``: the projector's focal length
    in pixels (plate mode needs it; placements mode estimates it when absent);
    ``projector_size``: (width, height), default from the session's device description;
    ``max_reproj_px`` / ``min_angle_deg``: triangulation rejection; ``poisson_depth``,
    ``poisson_trim``: Poisson octree depth and density trim; ``trim_distance``: mesh faces
    farther than this many point spacings from the cloud are cut."""

    mode: str = "auto"
    projector_focal_px: float | None = None
    projector_size: tuple[int, int] | None = None
    min_contrast: float = 0.05
    min_bit_contrast: float = 0.25
    auto_bits: bool = True
    min_views: int = 2
    max_reproj_px: float = 2.0
    min_angle_deg: float = 2.0
    normal_neighbours: int = 12
    poisson_depth: int = 8
    poisson_trim: float = 5.0
    trim_distance: float = 4.0
    num_threads: int = 1

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise RigError(f"procam.mode {self.mode!r} is unknown", f"use one of {MODES}")

    @property
    def decode_options(self) -> DecodeOptions:
        return DecodeOptions(self.min_contrast, self.min_bit_contrast, self.auto_bits)


# --- triangulation ------------------------------------------------------------------------


@dataclass(frozen=True)
class Observer:
    """A camera or a projector placement that observes projector blocks."""

    intrinsics: Intrinsics
    pose: Pose
    tolerance_px: float  # accepted reprojection error in this observer's pixels


def triangulate(obs: np.ndarray, observers: list[Observer]) -> np.ndarray:
    """Linear multi-view DLT, vectorised: pixels (N, V, 2) with NaN where unseen -> (N, 3).

    Rows are built in undistorted normalised coordinates, so distortion is handled and the
    system is well conditioned; unseen views contribute zero rows.
    """
    n, v, _ = obs.shape
    A = np.zeros((n, 2 * v, 4))
    for k, ob in enumerate(observers):
        seen = ~np.isnan(obs[:, k, 0])
        rays = ob.intrinsics.pixel_rays(obs[seen, k])
        xy = rays[:, :2] / rays[:, 2:3]
        P = np.hstack([ob.pose.R, ob.pose.t[:, None]])
        A[seen, 2 * k] = xy[:, :1] * P[2] - P[0]
        A[seen, 2 * k + 1] = xy[:, 1:2] * P[2] - P[1]
    A /= np.linalg.norm(A, axis=2, keepdims=True).clip(1e-12)
    _, _, vt = np.linalg.svd(A, full_matrices=False)
    h = vt[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[:, :3] / h[:, 3:4]


def check_points(
    points: np.ndarray, obs: np.ndarray, observers: list[Observer], min_angle_deg: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which points pass: in front of every observer, reprojection within each observer's
    tolerance, largest pairwise ray angle >= ``min_angle_deg``; and the RMS error (px)."""
    n = len(points)
    ok = np.all(np.isfinite(points), axis=1)
    sq = np.zeros(n)
    count = np.zeros(n)
    dirs = np.full((n, len(observers), 3), np.nan)
    for k, ob in enumerate(observers):
        seen = ~np.isnan(obs[:, k, 0])
        depth = points @ ob.pose.R[2] + ob.pose.t[2]
        ok &= ~seen | (depth > 0)
        uv = project(ob.intrinsics, ob.pose, points)
        err = np.linalg.norm(uv - obs[:, k], axis=1)
        with np.errstate(invalid="ignore"):
            ok &= ~seen | (err <= ob.tolerance_px)
        sq[seen] += np.nan_to_num(err[seen]) ** 2
        count[seen] += 1
        d = ob.pose.center - points
        dirs[seen, k] = d[seen] / np.linalg.norm(d[seen], axis=1, keepdims=True)
    cos_min = np.ones(n)
    for a in range(len(observers)):
        for b in range(a + 1, len(observers)):
            c = np.einsum("ij,ij->i", dirs[:, a], dirs[:, b])
            cos_min = np.fmin(cos_min, c)
    ok &= cos_min <= np.cos(np.radians(min_angle_deg))
    return ok, np.sqrt(sq / np.maximum(count, 1))


# --- correspondences ----------------------------------------------------------------------


def block_centroids(
    dec: GrayDecoding, merge: tuple[int, int] = (1, 1)
) -> dict[str, np.ndarray]:
    """Projector blocks seen by a view (``keys``) and the mean camera pixel (``xy``) and pixel
    count (``counts``) of the pixels decoded to each.

    ``merge`` coarsens the blocks (views of one placement may resolve different bit counts).
    Keys are ``col * rows + row`` in the coarsened blocks; (x, y) in COLMAP pixel coordinates.
    """
    rows_, cols_ = np.nonzero(dec.valid)
    col = dec.col[rows_, cols_] // merge[0]
    row = dec.row[rows_, cols_] // merge[1]
    n_rows = -(-dec.blocks[1] // merge[1])
    key = col * n_rows + row
    uniq, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    x = np.bincount(inv, weights=cols_ + 0.5) / counts
    y = np.bincount(inv, weights=rows_ + 0.5) / counts
    return {"keys": uniq, "xy": np.stack([x, y], axis=1), "counts": counts}


def _match(per_view: list[dict[str, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Union of block keys over views -> (keys (N,), pixels (N, V, 2) NaN where unseen)."""
    keys = np.unique(np.concatenate([c["keys"] for c in per_view]))
    obs = np.full((len(keys), len(per_view), 2), np.nan)
    for k, c in enumerate(per_view):
        obs[np.searchsorted(keys, c["keys"]), k] = c["xy"]
    return keys, obs


# --- frames -------------------------------------------------------------------------------


class FrameSource:
    """Linear frames of a session: the decode stage's output when present, else the files."""

    def __init__(self, session: Session, decoded_dir: Path | None) -> None:
        self.session = session
        self.decoded: dict[tuple[int, str], Any] = {}
        self.decoded_dir = decoded_dir
        if decoded_dir is not None and (decoded_dir / INDEX).is_file():
            for f in DecodeIndex.load(decoded_dir).frames:
                self.decoded[f.view, f.illumination] = f
        self.records: dict[tuple[int, str], FrameRecord] = {
            (r.view, r.illumination): r for r in session.frames
        }

    def labels(self, view: int) -> list[str]:
        return [lab for (v, lab) in self.records if v == view and is_structured(lab)]

    def load(self, view: int, label: str) -> tuple[np.ndarray, np.ndarray | None]:
        if (view, label) in self.decoded and self.decoded_dir is not None:
            return load_decoded(self.decoded_dir, self.decoded[view, label])
        record = self.records[view, label]
        path = self.session.root / record.path
        try:
            if path.suffix.lower() in LINEAR_SUFFIXES:
                return decode_linear(path, record, 0.98)
            return decode_raw(path, "linear", 0.98)
        except Exception as exc:  # rawpy, tifffile and numpy raise many types
            raise RigError(
                f"frame {record.path} (view {view}, {label}) cannot be read: {exc}",
                "run `rig session verify` and recapture the view with `rig capture --resume`",
            ) from exc


def has_gray_code(session: Session) -> bool:
    """Whether a session carries structured-light frames (it then takes the projector path,
    and those frames are not illuminations for the optimiser)."""
    return any(is_structured(r.illumination) and r.illumination not in ("white", "black")
               for r in session.frames)


def projector_size(session: Session, conf: ProcamConfig) -> tuple[int, int] | None:
    """The projector's (width, height): configuration, else the session's plan or device
    record (``session.yaml``)."""
    if conf.projector_size is not None:
        return (int(conf.projector_size[0]), int(conf.projector_size[1]))
    return session.info.projector_size


def placements(session: Session, conf: ProcamConfig, views: list[int]) -> dict[int, Any]:
    """View -> projector placement: the manifest's ``projector_placement`` or, in plate mode,
    the view itself."""
    recorded: dict[int, Any] = {}
    for r in session.frames:
        if r.view in views and PLACEMENT_KEY in r.extra:
            recorded[r.view] = json.dumps(r.extra[PLACEMENT_KEY])
    mode = conf.mode
    if mode == "auto":
        mode = "placements" if recorded else "plate"
    if mode == "plate":
        return {v: None for v in views}
    missing = [v for v in views if v not in recorded]
    if missing:
        raise RigError(
            f"views {missing} of {session.root} name no {PLACEMENT_KEY} in the manifest",
            "record the projector placement of every view, or set procam.mode: plate",
        )
    return recorded


# --- projector pose -----------------------------------------------------------------------


def resect(points: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, Pose]:
    """Camera matrix by normalised linear DLT from >= 6 non-coplanar points -> (K, pose)."""
    def normaliser(p: np.ndarray) -> np.ndarray:
        c = p.mean(axis=0)
        s = np.sqrt(p.shape[1]) / np.linalg.norm(p - c, axis=1).mean()
        T = np.eye(p.shape[1] + 1)
        T[:-1, :-1] *= s
        T[:-1, -1] = -s * c
        return T

    T3, T2 = normaliser(points), normaliser(xy)
    X = (np.hstack([points, np.ones((len(points), 1))])) @ T3.T
    x = (np.hstack([xy, np.ones((len(xy), 1))])) @ T2.T
    zeros = np.zeros_like(X)
    A = np.concatenate(
        [
            np.hstack([X, zeros, -x[:, :1] * X]),
            np.hstack([zeros, X, -x[:, 1:2] * X]),
        ]
    )
    P = np.linalg.solve(T2, np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 4) @ T3)
    if np.linalg.det(P[:, :3]) < 0:
        P = -P
    K, R = rq(P[:, :3])
    D = np.diag(np.sign(np.diag(K)))
    K, R = K @ D, D @ R
    t = np.linalg.solve(K, P[:, 3])
    return K / K[2, 2], Pose(R, t)


def projector_pose(
    points: np.ndarray, xy: np.ndarray, size: tuple[int, int], focal_px: float | None,
    tolerance_px: float,
) -> tuple[Intrinsics, Pose, int]:
    """Projector intrinsics and pose from 3-D points and their projector pixels: resection for
    an initial camera matrix, then ``cv2.solvePnPRansac`` with a square-pixel K (the given
    focal, else the resected one) and the principal point at the image centre; an unknown
    focal is finally refined jointly with the pose (``cv2.calibrateCamera``, one view of
    non-coplanar points, everything but f and the pose held fixed)."""
    if len(points) < 12:
        raise RigError(
            f"only {len(points)} triangulated points lit by one projector placement",
            "let more of the object be lit from each placement, or take more views per placement",
        )
    known = focal_px is not None
    if focal_px is None:
        K0, _ = resect(points, xy)
        focal_px = float(np.sqrt(abs(K0[0, 0] * K0[1, 1])))
    intr = Intrinsics.pinhole(size[0], size[1], focal_px)
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(
        points.astype(np.float64), xy.astype(np.float64), intr.K, None,
        reprojectionError=tolerance_px, iterationsCount=200, flags=cv2.SOLVEPNP_EPNP,
    )
    if not ok or inliers is None:
        raise RigError("the projector pose could not be estimated", "check the camera poses")
    idx = inliers[:, 0]
    obj, img = points[idx].astype(np.float32), xy[idx].astype(np.float32)
    if not known:
        flags = (
            cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT
            | cv2.CALIB_FIX_ASPECT_RATIO | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1
            | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3
        )
        _, K, _, rvecs, tvecs = cv2.calibrateCamera(
            [obj], [img], size, intr.K.copy(), np.zeros(5), flags=flags
        )
        intr = Intrinsics.pinhole(size[0], size[1], float(K[0, 0]))
        rvec, tvec = rvecs[0], tvecs[0]
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, intr.K, None, rvec, tvec)
    return intr, Pose(cv2.Rodrigues(rvec)[0], np.asarray(tvec, float).ravel()), len(idx)


def light_positions(
    view_placement: Mapping[int, Any], placement_poses: Mapping[Any, Pose]
) -> dict[int, np.ndarray]:
    """Per-view light position (world, metres): the optical centre of the projector
    placement that lit the view — the near point light of the optimiser's free-light mode."""
    return {
        v: placement_poses[p].center for v, p in view_placement.items() if p in placement_poses
    }


def read_light_positions(out_dir: Path) -> dict[int, np.ndarray]:
    """``lights.json`` written by :func:`procam_initial_mesh` -> view -> position."""
    data = json.loads((Path(out_dir) / LIGHTS).read_text())
    return {int(v): np.asarray(p, dtype=float) for v, p in data["positions"].items()}


# --- cloud -> mesh ------------------------------------------------------------------------


def oriented_normals(points: np.ndarray, towards: np.ndarray, k: int) -> np.ndarray:
    """PCA normals over ``k`` neighbours, flipped to face ``towards`` (directions to cameras)."""
    _, idx = cKDTree(points).query(points, k=min(k, len(points)))
    nb = points[idx] - points[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    normals = np.linalg.eigh(cov)[1][:, :, 0]
    flip = np.einsum("ij,ij->i", normals, towards) < 0
    normals[flip] *= -1
    return normals


def drop_outliers(points: np.ndarray, k: int = 8, factor: float = 3.0) -> np.ndarray:
    """Mask of points whose k-th neighbour is within ``factor`` x the median such distance."""
    d = cKDTree(points).query(points, k=min(k + 1, len(points)))[0][:, -1]
    return np.asarray(d <= factor * np.median(d))


def keep_large_pieces(mesh: trimesh.Trimesh, fraction: float) -> trimesh.Trimesh:
    """Drop connected pieces with fewer than ``fraction`` of the faces (labels from
    ``scipy.sparse.csgraph``: trimesh's ``split`` needs networkx, not a dependency)."""
    n = len(mesh.vertices)
    edges = mesh.edges_unique
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    face_label = labels[mesh.faces[:, 0]]
    counts = np.bincount(face_label)
    keep = counts[face_label] >= fraction * len(mesh.faces)
    out = mesh.submesh([np.nonzero(keep)[0]], append=True)
    assert isinstance(out, trimesh.Trimesh)
    return out


def poisson_surface(
    points: np.ndarray, normals: np.ndarray, depth: int, trim: float, num_threads: int
) -> trimesh.Trimesh:
    """Screened Poisson of the oriented cloud with ``pycolmap.poisson_meshing`` (CPU)."""
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "points.ply", Path(tmp) / "mesh.ply"
        write_oriented_ply(src, points, normals)
        options = pycolmap.PoissonMeshingOptions()
        options.depth, options.trim = depth, trim
        options.color, options.num_threads = False, num_threads
        pycolmap.poisson_meshing(src, dst, options)
        if not dst.is_file():
            raise RigError("Poisson meshing produced no mesh", "check recon/procam/points.ply")
        mesh = read_mesh(dst, process=True)
    if len(mesh.faces) == 0:
        raise RigError("Poisson meshing produced an empty mesh", "lower procam.poisson_trim")
    return mesh


def trim_to_cloud(mesh: trimesh.Trimesh, points: np.ndarray, factor: float) -> trimesh.Trimesh:
    """Cut faces whose vertices all lie farther than ``factor`` point spacings from the cloud
    (Poisson closes open scans with invented surface), then drop small leftover pieces."""
    tree = cKDTree(points)
    spacing = float(np.median(tree.query(points, k=2)[0][:, 1]))
    far = tree.query(mesh.vertices)[0] > factor * spacing
    keep = ~np.all(far[mesh.faces], axis=1)
    if not keep.any():
        raise RigError("trimming removed the whole mesh", "raise procam.trim_distance")
    out = mesh.submesh([np.nonzero(keep)[0]], append=True)
    assert isinstance(out, trimesh.Trimesh)
    return keep_large_pieces(out, 0.05)


# --- the stage ----------------------------------------------------------------------------


@dataclass
class _Cloud:
    points: list[np.ndarray]
    towards: list[np.ndarray]
    residuals: list[np.ndarray]


def _decode_views(
    source: FrameSource, views: list[int], size: tuple[int, int] | None, conf: ProcamConfig,
    out_dir: Path,
) -> dict[int, GrayDecoding]:
    (out_dir / "decoding").mkdir(exist_ok=True)
    decoded: dict[int, GrayDecoding] = {}
    for view in track(views, description="decoding Gray code"):
        labels = source.labels(view)
        if not labels:
            continue
        dec = decode_gray(labels, partial(source.load, view), size, conf.decode_options)
        np.savez_compressed(
            out_dir / "decoding" / f"view_{view:04d}.npz", col=dec.col, row=dec.row,
            valid=dec.valid, steps=[dec.col_step, dec.row_step],
        )
        log.info("view %d: %d pixels decoded (blocks of %dx%d projector pixels), rejected %s",
                 view, int(dec.valid.sum()), dec.col_step, dec.row_step, dec.rejected)
        decoded[view] = dec
    return decoded


def _intrinsics_for(view: int, intrinsics: Intrinsics | Mapping[int, Intrinsics],
                    shape: tuple[int, int]) -> Intrinsics:
    intr = intrinsics if isinstance(intrinsics, Intrinsics) else intrinsics[view]
    h, w = shape
    return intr if (intr.width, intr.height) == (w, h) else rescale(intr, w, h)


def _triangulate_group(
    views: list[int], decoded: dict[int, GrayDecoding], poses: Mapping[int, Pose],
    intrinsics: Intrinsics | Mapping[int, Intrinsics], projector: Observer | None,
    conf: ProcamConfig,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points, their directions to the cameras, RMS residuals, projector pixels and a mask of
    the points that passed, for the views lit by one projector placement."""
    step = (max(decoded[v].col_step for v in views), max(decoded[v].row_step for v in views))
    per_view = [
        block_centroids(decoded[v], (step[0] // decoded[v].col_step,
                                     step[1] // decoded[v].row_step))
        for v in views
    ]
    keys, obs = _match(per_view)
    observers = [
        Observer(_intrinsics_for(v, intrinsics, decoded[v].valid.shape), poses[v],
                 conf.max_reproj_px)
        for v in views
    ]
    n_rows = -(-decoded[views[0]].blocks[1] // (step[1] // decoded[views[0]].row_step))
    proj_xy = np.stack([(keys // n_rows + 0.5) * step[0], (keys % n_rows + 0.5) * step[1]], 1)
    need = conf.min_views
    if projector is not None:  # plate: the projector is a calibrated second view
        observers.append(Observer(projector.intrinsics, projector.pose,
                                  conf.max_reproj_px * max(step)))
        obs = np.concatenate([obs, proj_xy[:, None]], axis=1)
        need = 2
    enough = np.sum(~np.isnan(obs[:, :, 0]), axis=1) >= need
    obs, proj_xy = obs[enough], proj_xy[enough]
    points = triangulate(obs, observers)
    ok, rms = check_points(points, obs, observers, conf.min_angle_deg)
    towards = np.zeros_like(points)
    for k, v in enumerate(views):
        seen = ~np.isnan(obs[:, k, 0])
        d = poses[v].center - points[seen]
        towards[seen] += d / np.linalg.norm(d, axis=1, keepdims=True)
    return points, towards, rms, proj_xy, ok


def _procam(
    session: Session, poses: Mapping[int, Pose], intrinsics: Intrinsics | Mapping[int, Intrinsics],
    conf: ProcamConfig, out_dir: Path, decoded_dir: Path | None,
) -> None:
    source = FrameSource(session, decoded_dir)
    views = [v for v in session.views() if v in poses and source.labels(v)]
    unposed = [v for v in session.views() if v not in poses and source.labels(v)]
    if unposed:
        log.warning("views %s have Gray-code frames but no pose, not used", unposed)
    if not views:
        raise RigError(
            f"{session.root} has no Gray-code frames in views with a pose",
            "capture with a projector profile whose plan has structured_light.gray_code: true",
        )
    size = projector_size(session, conf)
    view_placement = placements(session, conf, views)
    plate = all(p is None for p in view_placement.values())
    offset = np.asarray(session.info.light_offset_m or (0.0, 0.0, 0.0), dtype=float)
    if plate and not offset.any():
        raise RigError(
            f"{session.root / 'session.yaml'} gives no light_mount.offset_m for the projector "
            "on the camera plate (camera and projector would share one centre)",
            "set light_mount.offset_m (projector lens relative to the camera lens, metres) in "
            "the profile, or record projector_placement per view",
        )
    if plate and conf.projector_focal_px is None:
        raise RigError(
            "a projector on the camera plate needs its focal length (procam.projector_focal_px)",
            "set it to throw ratio x projector width in pixels, or record projector_placement "
            "per view and move camera and projector alternately",
        )
    decoded = _decode_views(source, views, size, conf, out_dir)
    groups: dict[Any, list[int]] = defaultdict(list)
    for v in decoded:
        groups[view_placement[v] if not plate else v].append(v)
    cloud = _Cloud([], [], [])
    placement_poses: dict[Any, Pose] = {}
    info_placements: dict[str, Any] = {}
    for key, group in groups.items():
        projector = None
        psize = size or decoded[group[0]].projector_size
        if plate:
            assert conf.projector_focal_px is not None
            pose = poses[group[0]]
            projector = Observer(Intrinsics.pinhole(psize[0], psize[1], conf.projector_focal_px),
                                 Pose(pose.R, pose.t - offset), conf.max_reproj_px)
            placement_poses[key] = projector.pose
        elif len(group) < conf.min_views:
            log.warning("placement %s lights only view(s) %s, needs %d views: not used", key,
                        group, conf.min_views)
            continue
        pts, towards, rms, proj_xy, ok = _triangulate_group(
            group, decoded, poses, intrinsics, projector, conf)
        log.info("placement %s (views %s): %d of %d matches triangulated", key, group,
                 int(ok.sum()), len(ok))
        entry: dict[str, Any] = {"views": group, "matches": len(ok), "points": int(ok.sum()),
                                 "rms_px": float(np.median(rms[ok])) if ok.any() else None}
        if not plate and ok.any():
            step = max(max(decoded[v].col_step, decoded[v].row_step) for v in group)
            try:
                intr, ppose, inl = projector_pose(pts[ok], proj_xy[ok], psize,
                                                  conf.projector_focal_px,
                                                  conf.max_reproj_px * step)
            except RigError as exc:  # the mesh is still useful; the optimiser lacks a seed
                log.warning("placement %s: no projector pose (%s)", key, exc)
            else:
                placement_poses[key] = ppose
                entry |= {"projector_focal_px": float(intr.params[0]), "pnp_inliers": inl}
        if key in placement_poses:
            entry["projector_centre"] = [float(x) for x in placement_poses[key].center]
        info_placements[str(key)] = entry
        cloud.points.append(pts[ok])
        cloud.towards.append(towards[ok])
        cloud.residuals.append(rms[ok])
    if not cloud.points or sum(len(p) for p in cloud.points) < 100:
        raise RigError(
            f"too few 3-D points from the Gray code of {session.root} "
            f"({sum(len(p) for p in cloud.points)})",
            "check the camera poses, the projector focal length, and that views of one "
            "projector placement overlap",
        )
    points = np.concatenate(cloud.points)
    towards = np.concatenate(cloud.towards)
    keep = drop_outliers(points)
    points, towards = points[keep], towards[keep]
    normals = oriented_normals(points, towards, conf.normal_neighbours)
    write_oriented_ply(out_dir / POINTS, points, normals)
    mesh = poisson_surface(points, normals, conf.poisson_depth, conf.poisson_trim,
                           conf.num_threads)
    mesh = (
        trim_to_cloud(mesh, points, conf.trim_distance)
        if conf.trim_distance > 0
        else keep_large_pieces(mesh, 0.05)
    )
    mesh.export(out_dir / MESH)
    lights = light_positions(
        {v: (view_placement[v] if not plate else v) for v in decoded}, placement_poses
    )
    write_bytes_atomically(out_dir / LIGHTS, json.dumps({
        "mode": "plate" if plate else "placements",
        "positions": {str(v): [float(x) for x in p] for v, p in sorted(lights.items())},
    }, indent=1).encode())
    summary = {
        "method": "procam_gray_code+poisson", "mode": "plate" if plate else "placements",
        "points": len(points), "outliers_dropped": int((~keep).sum()),
        "median_rms_px": float(np.median(np.concatenate(cloud.residuals))),
        "vertices": len(mesh.vertices), "faces": len(mesh.faces),
        "placements": info_placements,
    }
    write_bytes_atomically(out_dir / SUMMARY, json.dumps(summary, indent=1).encode())
    log.info("procam initial mesh: %d points -> %d vertices", len(points), len(mesh.vertices))


def procam_initial_mesh(
    session: Session,
    poses: Mapping[int, Pose],
    intrinsics: Intrinsics | Mapping[int, Intrinsics],
    conf: ProcamConfig | Mapping[str, Any],
    out_dir: Path,
    decoded_dir: Path | None = None,
) -> Path:
    """Initial mesh of a projector session from its Gray-code frames (resumable stage).

    Frames come from the decode stage's ``decoded_dir`` when given (``recon/decoded``), else
    straight from the session's files. ``poses`` and ``intrinsics`` are per view (the poses
    stage's output). Returns ``out_dir/initial.ply``; ``lights.json`` beside it holds the
    projector light position of every view.
    """
    conf = conf if isinstance(conf, ProcamConfig) else ProcamConfig(**conf)
    out_dir = Path(out_dir)
    inputs = [session.root / "manifest.jsonl", session.root / "session.yaml"]
    if decoded_dir is not None:
        inputs.append(Path(decoded_dir) / INDEX)
    state = asdict(conf) | {
        "poses": {str(v): [p.R.tolist(), p.t.tolist()] for v, p in sorted(poses.items())},
        "intrinsics": str(intrinsics),
    }
    run_stage(
        "initial_mesh_procam", state, inputs, out_dir,
        lambda: _procam(session, poses, intrinsics, conf, out_dir, decoded_dir),
    )
    return out_dir / MESH
