"""COLMAP text models: written and read through pycolmap, exchanged with pycolmap itself both
ways, known poses written by hand (no points3D.txt), and bad models named with the fix."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

from core.errors import RigError
from reconstruct.model.camera import (
    CAMERA_MODELS,
    Intrinsics,
    Pose,
    read_colmap_text,
    write_colmap_text,
)

PARAMS = {
    "SIMPLE_PINHOLE": (400.5, 160.0, 120.0),
    "PINHOLE": (400.5, 401.25, 160.0, 120.0),
    "SIMPLE_RADIAL": (400.5, 160.0, 120.0, -0.05),
    "RADIAL": (400.5, 160.0, 120.0, -0.05, 0.01),
    "OPENCV": (400.5, 401.25, 160.0, 120.0, -0.05, 0.01, 1e-4, -2e-4),
}


def random_pose(seed: int) -> Pose:
    rng = np.random.default_rng(seed)
    return Pose(Rotation.random(random_state=seed).as_matrix(), rng.normal(size=3))


def test_every_model_round_trips_exactly(tmp_path: Path) -> None:
    assert set(PARAMS) == set(CAMERA_MODELS)
    cameras = {i + 1: Intrinsics(m, 320, 240, p) for i, (m, p) in enumerate(PARAMS.items())}
    images = {10 + c: (c, f"view_{c:04d}.png", random_pose(c)) for c in cameras}
    write_colmap_text(tmp_path, cameras, images)
    cams_back, images_back = read_colmap_text(tmp_path)
    assert cams_back == cameras
    assert images_back.keys() == images.keys()
    for iid, (cid, name, pose) in images.items():
        cid_back, name_back, pose_back = images_back[iid]
        assert (cid_back, name_back) == (cid, name)
        np.testing.assert_allclose(pose_back.R, pose.R, atol=1e-15)
        np.testing.assert_allclose(pose_back.t, pose.t, atol=1e-15)


def test_pycolmap_reads_what_the_project_writes(tmp_path: Path) -> None:
    pose = random_pose(3)
    radial = Intrinsics("RADIAL", 320, 240, PARAMS["RADIAL"])
    write_colmap_text(tmp_path, {2: radial}, {7: (2, "view_0006.png", pose)})
    model = pycolmap.Reconstruction(tmp_path)
    camera, image = model.cameras[2], model.images[7]
    assert (camera.model.name, camera.width, camera.height) == ("RADIAL", 320, 240)
    np.testing.assert_array_equal(camera.params, PARAMS["RADIAL"])
    assert (image.name, image.camera_id) == ("view_0006.png", 2)
    np.testing.assert_allclose(image.cam_from_world().matrix(), np.c_[pose.R, pose.t], atol=1e-15)
    # and the projection agrees with the project's camera model
    point = np.array([[0.1, -0.2, 4.0]])
    np.testing.assert_allclose(camera.img_from_cam(point), radial.project_camera(point), atol=1e-9)


def test_the_project_reads_a_model_pycolmap_writes_with_points(tmp_path: Path) -> None:
    model = pycolmap.Reconstruction()
    params = list(PARAMS["OPENCV"])
    camera = pycolmap.Camera(camera_id=1, model="OPENCV", width=320, height=240, params=params)
    model.add_camera_with_trivial_rig(camera)
    pose = random_pose(5)
    image = pycolmap.Image(
        name="a.png", camera_id=1, image_id=4, keypoints=np.array([[10.0, 20.0]])
    )
    model.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(pose.R), pose.t))
    track = pycolmap.Track()
    track.add_element(4, 0)
    model.add_point3D(np.array([0.0, 0.0, 1.0]), track)
    model.write_text(tmp_path)
    cameras, images = read_colmap_text(tmp_path)
    assert cameras == {1: Intrinsics("OPENCV", 320, 240, PARAMS["OPENCV"])}
    cid, name, pose_back = images[4]
    assert (cid, name) == (1, "a.png")
    np.testing.assert_allclose(pose_back.R, pose.R, atol=1e-15)


def test_known_poses_written_by_hand_without_points3d(tmp_path: Path) -> None:
    (tmp_path / "cameras.txt").write_text("# a comment\n1 PINHOLE 160 120 100 100 80 60\n")
    (tmp_path / "images.txt").write_text("3 1 0 0 0 0.5 0 2 1 v003_white.npy\n\n")
    cameras, images = read_colmap_text(tmp_path)
    assert cameras[1] == Intrinsics.pinhole(160, 120, 100.0)
    cid, name, pose = images[3]
    assert (cid, name) == (1, "v003_white.npy")
    np.testing.assert_array_equal(pose.R, np.eye(3))
    np.testing.assert_array_equal(pose.t, [0.5, 0.0, 2.0])
    assert not (tmp_path / "points3D.txt").exists()  # the session's folder is left as it was


def test_bad_models_name_the_folder_and_the_fix(tmp_path: Path) -> None:
    with pytest.raises(RigError, match=r"cameras.txt is missing — a COLMAP text model needs"):
        read_colmap_text(tmp_path)
    (tmp_path / "cameras.txt").write_text("1 PINHOLE 160 120 100 100 80 60\n")
    (tmp_path / "images.txt").write_text("3 1 0 zero 0 0.5 0 2 1 v.npy\n\n")
    with pytest.raises(RigError, match=f"{tmp_path} is not a valid COLMAP text model: .*format"):
        read_colmap_text(tmp_path)
    (tmp_path / "cameras.txt").write_text("1 FULL_OPENCV 160 120 " + "1 " * 12 + "\n")
    (tmp_path / "images.txt").write_text("")
    with pytest.raises(RigError, match="camera model 'FULL_OPENCV' is not supported"):
        read_colmap_text(tmp_path)
