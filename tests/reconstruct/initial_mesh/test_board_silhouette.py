"""Board-aware silhouettes and the dense initial mesh of an object standing on a printed
ChArUco board: synthetic images of the print for the pieces, the simulated rig (real Bayer
DNGs, decoded) for the whole stage against the true silhouettes and surface."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh
import yaml

from core.errors import RigError
from core.files import sha256_file
from core.manifest import FrameRecord, append_manifest
from drivers.sim.rig import SimRig
from reconstruct.frames import decode
from reconstruct.frames.decode import DecodeIndex, load_frame
from reconstruct.initial_mesh import stage as initial_mesh
from reconstruct.initial_mesh.dense.board_silhouette import (
    board_silhouette,
    expected_ground,
    fit_shading,
)
from reconstruct.initial_mesh.dense.poisson import read_mesh
from reconstruct.initial_mesh.dense.silhouette import silhouette
from reconstruct.model import render
from reconstruct.model.camera import Intrinsics, Pose, write_colmap_text
from reconstruct.model.raycast import RayCaster
from reconstruct.poses import stage as poses
from reconstruct.poses.board import BoardSpec, board_texture

SPEC = BoardSpec.fit_paper("A3")  # 10x7 squares of 39 mm, as profiles/sim.yaml
PAPER, INK = 0.85, 0.04


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def test_fit_shading_ignores_outliers() -> None:
    h, w = 60, 80
    rows, cols = np.mgrid[0:h, 0:w]
    k = 0.5 + 0.3 * (cols / w) - 0.2 * (rows / h) ** 2
    values = k.copy()
    values[20:40, 30:50] = 0.05  # an object (or a shadow) over a fifth of the paper
    shading, spread = fit_shading(values.ravel(), rows.ravel(), cols.ravel(), (h, w))
    assert np.abs(shading / k - 1).max() < 1e-3 and spread < 0.01


def synthetic_view(
    rng: np.random.Generator,
) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, Intrinsics, Pose]:
    """The board seen obliquely under smooth shading in two lights, with a coloured disc
    standing in for the object and a shadow beside it."""
    intr = Intrinsics.pinhole(240, 180, 300.0)
    pose = Pose.look_at(np.array([0.05, -0.35, 0.4]), np.zeros(3))
    paper, cover = expected_ground(SPEC, intr, pose)
    rows, cols = np.mgrid[0:180, 0:240]
    shading = 0.6 * (1.0 - 0.4 * ((cols - 100) / 240) ** 2 - 0.3 * (rows / 180))
    disc = np.hypot(cols - 120, rows - 90) < 30
    shadow = (np.hypot(cols - 85, rows - 100) < 25) & ~disc
    images = []
    for gain, colour in ((np.array([0.5, 1.0, 0.7]), np.array([0.6, 0.3, 0.2])),
                         (np.array([1.0, 0.6, 0.3]), np.array([0.5, 0.35, 0.3]))):
        board = cover * (INK + (PAPER - INK) * paper)
        img = (shading * board)[..., None] * gain
        img[shadow] *= 0.3
        img[disc] = (shading[disc, None] * colour) * gain
        img += rng.normal(0.0, 0.004, img.shape)
        images.append(img.astype(np.float32))
    return images, disc, shadow, intr, pose


def test_board_silhouette_finds_the_object_on_the_print() -> None:
    images, disc, shadow, intr, pose = synthetic_view(np.random.default_rng(1))
    mask = board_silhouette(images, SPEC, intr, pose)
    assert (disc & ~mask).sum() < 0.02 * disc.sum()
    # the shadow counts as object (conservative: other views carve it), the print does not
    # (the blur of the test widens the outline by a pixel)
    assert iou(mask, disc | shadow) > 0.9
    near = cv2.dilate((disc | shadow).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    assert (mask & ~near).sum() == 0
    assert iou(silhouette(images), disc) < 0.5  # the dark-background rule takes the paper


def test_view_without_the_board_keeps_the_dark_background_rule() -> None:
    images, disc, _, intr, _ = synthetic_view(np.random.default_rng(2))
    dark = [np.where(disc[..., None], img, 0.0).astype(np.float32) for img in images]
    away = Pose.look_at(np.array([2.0, 2.0, 0.3]), np.array([3.0, 3.0, 0.3]))
    mask = board_silhouette(dark, SPEC, intr, away)
    assert np.array_equal(mask, silhouette(dark)) and iou(mask, disc) > 0.95


def test_board_key_of_the_mesh_config() -> None:
    as_dict = initial_mesh.mesh_config({"board": SPEC})
    assert as_dict.board == SPEC.to_dict() and as_dict.board_spec() == SPEC
    assert initial_mesh.MeshConfig().board_spec() is None
    with pytest.raises(RigError, match="board"):
        initial_mesh.mesh_config({"board": {"squares": [1, 1]}})


def sim_session(root: Path, views: int) -> tuple[Path, SimRig]:
    """A sim capture on the board: two bulb LEDs per view, decoded, with the true poses."""
    texture, extent = board_texture(SPEC, 6000.0)
    rig = SimRig({
        "views": views, "subdivisions": 4,
        "trajectory": {"radius_m": 0.55, "elevations_deg": [30, 50]},
        "camera": {"width": 320, "height": 240, "focal_px": 400.0, "supersample": 2},
        "ground": {"texture": texture, "extent": list(extent), "paper": PAPER, "ink": INK},
    }, seed=0)
    root.mkdir(parents=True)
    intr = rig.intrinsics
    (root / "session.yaml").write_text(yaml.safe_dump({
        "rig": "sim", "board": SPEC.to_dict(),
        "intrinsics": {"model": intr.model, "width": intr.width, "height": intr.height,
                       "params": list(intr.params)},
    }))
    frame = 0
    for view in range(views):
        rig.goto_view(view)
        for name in list(rig.light.illuminations)[:2]:
            rig.light.set_illumination(name)
            shot = rig.camera.capture(root / "raw", f"v{view:03d}_{name}")
            append_manifest(root, FrameRecord(
                frame, view, name, shot.paths[0].relative_to(root).as_posix(),
                sha256_file(shot.paths[0]), shot.exposure_s, shot.iso, shot.timestamp,
                dict(shot.extra)))
            frame += 1
    write_colmap_text(root / "poses", {1: intr},
                      {v + 1: (1, f"view_{v:04d}", p) for v, p in enumerate(rig.poses)})
    decode.run({}, root, root / "recon" / "decoded")
    return root, rig


def true_silhouettes(rig: SimRig, mesh: trimesh.Trimesh | None = None) -> list[np.ndarray]:
    """Coverage > 1/2 of the true mesh (or ``mesh``) in every view, the board in front."""
    m = rig.scene if mesh is None else mesh
    caster = RayCaster(np.asarray(m.vertices), np.asarray(m.faces))
    ground = rig.ground if mesh is None else None
    return [render.trace_view(caster, rig.intrinsics, p, 3, ground=ground).coverage() > 0.5
            for p in rig.poses]


@pytest.mark.slow
def test_sim_board_silhouettes_and_initial_mesh(tmp_path: Path) -> None:
    root, rig = sim_session(tmp_path / "s", views=12)
    decoded = root / "recon" / "decoded"
    index = DecodeIndex.load(decoded)
    truth = true_silhouettes(rig)
    scores, before = [], []
    for view, pose in enumerate(rig.poses):
        images = [load_frame(decoded, f)[0] for f in index.frames if f.view == view]
        scores.append(iou(board_silhouette(images, SPEC, rig.intrinsics, pose), truth[view]))
        before.append(iou(silhouette(images), truth[view]))
    print(f"silhouette IoU on the board: mean {np.mean(scores):.3f}, worst {min(scores):.3f} "
          f"(dark-background rule: mean {np.mean(before):.3f})")
    assert np.mean(scores) > 0.88 and min(scores) > 0.8
    assert np.mean(before) < 0.6

    posed = poses.run({}, root, decoded, root / "recon" / "poses")
    out = initial_mesh.run({"method": "visual_hull", "board": SPEC}, decoded, posed,
                           root / "recon" / "mesh")
    mesh = read_mesh(out)
    true_mesh = trimesh.Trimesh(rig.scene.vertices, rig.scene.faces, process=False)
    _, to_truth, _ = trimesh.proximity.closest_point(true_mesh, np.asarray(mesh.vertices))
    _, to_mesh, _ = trimesh.proximity.closest_point(mesh, np.asarray(true_mesh.vertices))
    hull = true_silhouettes(rig, mesh)
    hull_iou = [iou(h, t) for h, t in zip(hull, truth, strict=True)]
    print(f"initial mesh on the board: mean distance to the truth {1000 * to_truth.mean():.2f} "
          f"mm, from it {1000 * to_mesh.mean():.2f} mm; its silhouettes' IoU mean "
          f"{np.mean(hull_iou):.3f}, worst {min(hull_iou):.3f}")
    assert mesh.is_watertight
    assert 1000 * to_truth.mean() < 3.0 and 1000 * to_mesh.mean() < 3.0
    assert min(hull_iou) > 0.9
    # no board left in the mesh: nothing under it, nothing beyond the object's footprint
    lo, hi = true_mesh.bounds
    assert mesh.vertices[:, 2].min() >= 0.0
    assert (mesh.bounds[0][:2] > lo[:2] - 0.01).all() and (mesh.bounds[1][:2] < hi[:2] + 0.01).all()
