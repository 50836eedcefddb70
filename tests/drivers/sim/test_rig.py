"""SimRig wiring: protocols, trajectory, light on the plate, ground truth, spectrometer,
projector, scenes and config errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from calibration.spectra import resample
from core.errors import RigError
from drivers.protocols import Camera, LightSource, Projector, Spectrometer
from drivers.sim import Scene, SimRig, make_scene
from reconstruct.model.camera import project, read_colmap_text

SMALL = {
    "scene": "blob",
    "subdivisions": 5,
    "views": 6,
    "camera": {"width": 96, "height": 72, "focal_px": 120.0},
    "projector": {"width": 64, "height": 48, "focal_px": 80.0},
}


@pytest.fixture(scope="module")
def rig() -> SimRig:
    return SimRig(SMALL, seed=3)


def test_devices_implement_the_protocols(rig: SimRig) -> None:
    assert isinstance(rig.camera, Camera)
    assert isinstance(rig.light, LightSource)
    assert isinstance(rig.projector, Projector)
    assert isinstance(rig.spectrometer, Spectrometer)
    assert set(rig.light.illuminations) == {"LED1", "LED2", "LED3"}
    assert rig.camera.describe()["serial"]


def test_views_look_at_the_object_and_light_rides_on_the_plate(rig: SimRig) -> None:
    assert len(rig.poses) == 6
    assert rig.light_offset is not None
    for v, pose in enumerate(rig.poses):
        uv = rig.intrinsics.project_camera(pose.to_camera(np.zeros((1, 3))))[0]
        np.testing.assert_allclose(uv, [48, 36], atol=1e-6)
        assert np.linalg.norm(pose.center) == pytest.approx(0.5)
        np.testing.assert_allclose(rig.light_positions[v], pose.light_position(rig.light_offset))
    rig.goto_view(4)
    assert rig.camera.pose is rig.poses[4]
    np.testing.assert_allclose(rig.light.position, rig.light_positions[4])
    np.testing.assert_allclose(
        rig.projector.pose.center, rig.poses[4].light_position(np.array([-0.08, 0, 0]))
    )
    with pytest.raises(RigError, match="view 6"):
        rig.goto_view(6)


def test_each_view_sees_the_lit_object(rig: SimRig) -> None:
    rig.light.set_illumination("LED3")
    for v in range(len(rig.poses)):
        rig.goto_view(v)
        y = rig.camera.render_linear()
        lit = y.max(axis=2) > 0
        assert 0.05 < lit.mean() < 0.9
        assert not lit[0].any() and not lit[-1].any()  # the object fits in the frame
    rig.light.off()
    assert rig.camera.render_linear().max() == 0.0


def test_ground_truth_round_trip(rig: SimRig, tmp_path: Path) -> None:
    rig.write_ground_truth(tmp_path)
    scene = Scene.load(tmp_path)
    np.testing.assert_allclose(scene.vertices, rig.scene.vertices)
    np.testing.assert_array_equal(scene.faces, rig.scene.faces)
    np.testing.assert_allclose(scene.reflectance, rig.scene.reflectance, atol=1e-7)
    cameras, images = read_colmap_text(tmp_path / "poses")
    assert cameras[1] == rig.intrinsics
    assert [images[k][1] for k in sorted(images)][:2] == ["view_0000.png", "view_0001.png"]
    for k, (_, _, pose) in images.items():
        np.testing.assert_allclose(pose.center, rig.poses[k - 1].center, atol=1e-9)
    assert (tmp_path / "rig.yaml").read_text().count("light_offset_m: null") == 0


def test_spectrometer_measures_the_light(rig: SimRig) -> None:
    rig.light.off()
    rig.spectrometer.measure_dark()
    rig.light.set_illumination("LED1")
    spec = rig.spectrometer.measure()
    assert spec.dark_subtracted and not spec.saturated
    grid = resample(spec.wavelengths_nm, spec.values, source="sim spectrometer")
    truth = rig.light.spd()
    corr = np.corrcoef(grid, truth)[0, 1]
    assert corr > 0.99
    rig.light.off()


def test_projector_pattern_lights_the_scene(rig: SimRig) -> None:
    rig.goto_view(0)
    rig.light.off()
    rig.projector.blank()
    assert rig.camera.render_linear().max() == 0.0
    # Light only the projector columns left of the object's centre.
    centre = project(rig.projector.intrinsics, rig.projector.pose, np.zeros((1, 3)))[0, 0]
    left = np.zeros((48, 64, 3))
    left[:, : int(centre)] = 1.0
    rig.projector.show(left)
    half = rig.camera.render_linear()
    rig.projector.show(np.ones((48, 64), dtype=float))
    full = rig.camera.render_linear()
    assert 0 < half.sum() < 0.8 * full.sum()
    assert np.all(half <= full + 1e-12)
    rig.projector.blank()
    with pytest.raises(RigError, match="pattern"):
        rig.projector.show(np.ones((10, 10)))


def test_scenes_are_seeded_and_distinct(tmp_path: Path) -> None:
    a, b = make_scene("torus", seed=1, subdivisions=5), make_scene("torus", seed=1, subdivisions=5)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.reflectance, b.reflectance)
    c = make_scene("torus", seed=2, subdivisions=5)
    assert not np.allclose(a.vertices, c.vertices)
    blob = make_scene("blob", seed=1, subdivisions=5)
    assert set(np.unique(blob.patch)) == set(range(24))
    assert np.all(np.abs(blob.vertices).max(axis=0) < 0.1)
    with pytest.raises(RigError, match="unknown sim scene"):
        make_scene("teapot")


def test_bad_config_is_refused() -> None:
    with pytest.raises(RigError, match="'sim.colour' is not known"):
        SimRig({"scene": "blob", "colour": 1})
    with pytest.raises(RigError, match="sim.camera"):
        SimRig({"subdivisions": 3, "camera": {"width": 33}})
    with pytest.raises(RigError, match="neither a built-in"):
        SimRig({"scene": "/nonexistent/folder"})


def test_free_lights_differ_per_view() -> None:
    free = SimRig({**SMALL, "subdivisions": 3, "trajectory": {"light": "free"}}, seed=0)
    assert free.light_offset is None
    d = np.linalg.norm(free.light_positions, axis=1)
    np.testing.assert_allclose(d, 0.45)
    assert len({tuple(np.round(p, 6)) for p in free.light_positions}) == 6


def test_views_step_in_and_out_through_the_distances() -> None:
    traj = {"distances_m": [0.35, 0.5, 0.65], "elevations_deg": [20, 45]}
    stepped = SimRig({**SMALL, "subdivisions": 3, "trajectory": traj}, seed=0)
    distance = [float(np.linalg.norm(p.center)) for p in stepped.poses]
    np.testing.assert_allclose(distance, [0.35, 0.5, 0.65, 0.35, 0.5, 0.65])
    for pose in stepped.poses:  # still looking at the object
        np.testing.assert_allclose(pose.to_camera(np.zeros((1, 3)))[0, :2], 0.0, atol=1e-12)
    with pytest.raises(RigError, match="distances_m"):
        SimRig({**SMALL, "subdivisions": 3, "trajectory": {"distances_m": [0.4, -0.1]}})


def test_same_seed_same_capture_bytes(rig: SimRig, tmp_path: Path) -> None:
    twin = SimRig(SMALL, seed=3)
    files = []
    for k, r in enumerate((rig, twin)):
        r.goto_view(2)
        r.light.set_illumination("LED1")
        files.append(r.camera.capture(tmp_path / str(k), "v002_LED1").paths[0].read_bytes())
    assert files[0] == files[1]
    other = SimRig({**SMALL, "subdivisions": 4}, seed=4)
    other.goto_view(2)
    other.light.set_illumination("LED1")
    assert other.camera.capture(tmp_path / "o", "v002_LED1").paths[0].read_bytes() != files[0]


def test_free_projector_placements(tmp_path: Path) -> None:
    """Camera and projector moved alternately: the projector holds its pose for the views of
    a placement, faces the object from its own side, and the truth records it."""
    projector = {"width": 64, "height": 48, "focal_px": 80.0, "placements": 3}
    rig = SimRig({**SMALL, "subdivisions": 3, "projector": projector}, seed=0)
    assert [rig.projector_placement(v) for v in range(6)] == [0, 0, 1, 1, 2, 2]
    centres = []
    for view in range(6):
        rig.goto_view(view)
        centres.append(rig.projector.pose.center.copy())
        # the projector lights the object and is not where the camera is
        target = np.asarray(rig.trajectory.target_m)
        assert rig.projector.intrinsics.in_image(
            project(rig.projector.intrinsics, rig.projector.pose, target[None])
        )[0]
        assert np.linalg.norm(centres[-1] - rig.poses[view].center) > 0.05
    np.testing.assert_allclose(centres[0], centres[1])
    assert np.linalg.norm(centres[0] - centres[2]) > 0.3
    rig.write_ground_truth(tmp_path)
    truth = yaml.safe_load((tmp_path / "rig.yaml").read_text())
    assert truth["view_placement"] == [0, 0, 1, 1, 2, 2]
    np.testing.assert_allclose(truth["projector_placements"][2]["centre_m"], centres[4])
    with pytest.raises(RigError, match="views_per_placement"):
        SimRig({**SMALL, "subdivisions": 3, "projector": {"placements": 4}})
