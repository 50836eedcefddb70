"""Incremental structure from motion with pycolmap (CPU), scaled to metres by the session's
measured camera distances when it has any."""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pycolmap

from core.errors import RigError
from core.session import Session
from core.session_info import SessionInfo
from reconstruct.frames.decode import SFM_DIR, DecodeIndex
from reconstruct.model.camera import CAMERA_MODELS, Intrinsics, Pose
from reconstruct.poses.config import MIN_VIEWS, PosesConfig
from reconstruct.poses.output import PoseSummary
from reconstruct.stages.resumable import quiet_colmap

log = logging.getLogger("reconstruct.poses.sfm")


@dataclass
class SfmResult:
    """Registered image name -> (intrinsics at the SfM image size, pose); sparse points."""

    cameras: dict[str, tuple[Intrinsics, Pose]]
    points: np.ndarray
    mean_reprojection_error_px: float


def session_intrinsics(info: SessionInfo) -> Intrinsics | None:
    """The camera intrinsics session.yaml gives, None without any."""
    spec = info.intrinsics
    return None if spec is None else Intrinsics(spec.model, spec.width, spec.height, spec.params)


def rescale(intr: Intrinsics, width: int, height: int) -> Intrinsics:
    """The same camera at another image size (pixel edges scale, so do principal points)."""
    if (width, height) == (intr.width, intr.height):
        return intr
    sx, sy = width / intr.width, height / intr.height
    scaled = []
    for name, value in zip(CAMERA_MODELS[intr.model], intr.params, strict=True):
        if name in ("f", "fx", "cx"):
            value *= sx if name != "f" else (sx + sy) / 2
        elif name in ("fy", "cy"):
            value *= sy
        scaled.append(float(value))
    return Intrinsics(intr.model, width, height, tuple(scaled))


def run_sfm(
    image_dir: Path,
    names: Sequence[str],
    conf: PosesConfig,
    work_dir: Path,
    intrinsics: Intrinsics | None = None,
) -> SfmResult:
    """SIFT + matching + incremental mapping with pycolmap on CPU; the largest model wins.

    ``intrinsics`` (at the images' size) are used as a fixed shared camera when given.
    """
    with quiet_colmap():
        return _sfm(image_dir, names, conf, work_dir, intrinsics)


def _sfm(
    image_dir: Path,
    names: Sequence[str],
    conf: PosesConfig,
    work_dir: Path,
    intrinsics: Intrinsics | None,
) -> SfmResult:
    database = work_dir / "database.db"
    database.unlink(missing_ok=True)
    reader = pycolmap.ImageReaderOptions()
    if intrinsics is not None:
        reader.camera_model = intrinsics.model
        reader.camera_params = ",".join(repr(float(p)) for p in intrinsics.params)
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = conf.num_threads
    extraction.sift.max_num_features = conf.max_features
    extraction.sift.estimate_affine_shape = conf.affine_sift
    extraction.sift.domain_size_pooling = conf.affine_sift
    pycolmap.extract_features(
        database, image_dir, image_names=list(names), camera_mode=pycolmap.CameraMode.SINGLE,
        reader_options=reader, extraction_options=extraction, device=pycolmap.Device.cpu,
    )
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = conf.num_threads
    matching.guided_matching = conf.guided_matching
    matcher = conf.matcher if conf.matcher != "auto" else (
        "exhaustive" if len(names) <= 60 else "sequential"
    )
    if matcher == "exhaustive":
        pycolmap.match_exhaustive(database, matching_options=matching, device=pycolmap.Device.cpu)
    else:
        pycolmap.match_sequential(database, matching_options=matching, device=pycolmap.Device.cpu)
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = conf.num_threads
    options.min_model_size = MIN_VIEWS
    options.mapper.init_min_num_inliers = conf.init_min_inliers
    options.mapper.abs_pose_min_num_inliers = max(15, conf.init_min_inliers // 2)
    if intrinsics is not None and not conf.refine_intrinsics:
        options.ba_refine_focal_length = False
        options.ba_refine_principal_point = False
        options.ba_refine_extra_params = False
    models = pycolmap.incremental_mapping(database, image_dir, work_dir / "sparse", options)
    if not models:
        raise RigError(
            f"structure from motion registered no views of {image_dir}",
            "the views must overlap and show texture; capture more views or give known poses "
            "in SESSION/poses/",
        )
    rec = max(models.values(), key=lambda r: r.num_reg_images())
    cameras: dict[str, tuple[Intrinsics, Pose]] = {}
    for image in rec.images.values():
        if not image.has_pose:
            continue
        cam = image.camera
        rigid = image.cam_from_world()
        intr = Intrinsics(
            cam.model.name, int(cam.width), int(cam.height), tuple(float(p) for p in cam.params)
        )
        cameras[image.name] = (
            intr, Pose(np.asarray(rigid.rotation.matrix()), np.asarray(rigid.translation))
        )
    points = np.array([p.xyz for p in rec.points3D.values()], dtype=float).reshape(-1, 3)
    return SfmResult(cameras, points, float(rec.compute_mean_reprojection_error()))


def metric_scale(info: SessionInfo, centres: Mapping[int, np.ndarray]) -> float | None:
    """Median of measured / reconstructed camera-centre distances, None without any."""
    if not info.known_distances:
        return None
    ratios = []
    for entry in info.known_distances:
        a, b = entry.views
        metres = entry.metres
        if a in centres and b in centres:
            ratios.append(metres / float(np.linalg.norm(centres[a] - centres[b])))
        else:
            log.warning("known distance between views %d and %d: a view is not registered", a, b)
    return float(np.median(ratios)) if ratios else None


def full_size(decoded: DecodeIndex, view: int) -> tuple[int, int]:
    first = next(f for f in decoded.frames if f.view == view)
    return first.width, first.height


def sfm_poses(
    session: Session,
    decoded: DecodeIndex,
    decoded_dir: Path,
    conf: PosesConfig,
    out_dir: Path,
    intrinsics: Intrinsics | None = None,
    only: Sequence[int] | None = None,
) -> tuple[dict[int, tuple[Intrinsics, Pose]], PoseSummary, np.ndarray]:
    """SfM poses (of the views ``only``, when given); ``intrinsics`` (full size) override the
    session's when given."""
    views = sorted(decoded.sfm_images if only is None else set(only) & set(decoded.sfm_images))
    full = full_size(decoded, views[0])
    names = [decoded.sfm_images[v] for v in views]
    sfm_image = cv2.imread(str(decoded_dir / SFM_DIR / names[0]), cv2.IMREAD_UNCHANGED)
    if sfm_image is None:
        raise RigError(f"{decoded_dir / SFM_DIR / names[0]} cannot be read", "delete recon/decoded")
    h, w = sfm_image.shape[:2]
    given = intrinsics if intrinsics is not None else session_intrinsics(session.info)
    with tempfile.TemporaryDirectory(dir=out_dir) as tmp:
        result = run_sfm(
            decoded_dir / SFM_DIR, names, conf, Path(tmp),
            rescale(given, w, h) if given is not None else None,
        )
    by_name = {decoded.sfm_images[v]: v for v in views}
    out = {
        by_name[n]: (rescale(intr, *full), pose) for n, (intr, pose) in result.cameras.items()
    }
    scale = metric_scale(session.info, {v: p.center for v, (_, p) in out.items()})
    points = result.points
    if scale is not None:
        out = {v: (i, Pose(p.R, p.t * scale)) for v, (i, p) in out.items()}
        points = points * scale
    summary = PoseSummary(
        "sfm", len(out), len(views), sorted(out), sorted(set(views) - set(out)),
        result.mean_reprojection_error_px, "metric" if scale else "relative", scale or 1.0,
        "given" if intrinsics is not None else "session" if given is not None else "sfm",
        views={str(v): {"source": "sfm"} for v in sorted(out)},
    )
    return out, summary, points
