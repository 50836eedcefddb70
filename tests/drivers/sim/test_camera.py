"""SimCamera: renders match the analytic model, DNGs decode to the rendered values, noise,
saturation, shadows and determinism."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rawpy
from test_dng import decode

from calibration.defaults import colorchecker_reflectances
from core.errors import RigError
from drivers.sim.camera import SensorConfig, SimCamera
from drivers.sim.light import SimLight
from drivers.sim.scene import Scene, make_scene
from reconstruct.model import forward
from reconstruct.model.camera import Pose

HEIGHT_M = 0.4
SENSOR = SensorConfig(width=160, height=120, focal_px=400.0)


@pytest.fixture(scope="module")
def chart() -> Scene:
    return make_scene("chart")


def _camera(scene: Scene, light_pos: np.ndarray, sensor: SensorConfig = SENSOR) -> SimCamera:
    light = SimLight()
    light.set_illumination("LED3")
    light.position = light_pos
    cam = SimCamera(scene, light, None, sensor, seed=1)
    cam.set_pose(Pose.look_at(np.array([0.0, 0.0, HEIGHT_M]), np.zeros(3), up=(0.0, 1.0, 0.0)))
    return cam


def _analytic(cam: SimCamera, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel-centre model on the z = 0 chart, and a mask of pixels well inside patches."""
    intr, pose = cam.intrinsics, cam.pose
    rows, cols = np.indices((intr.height, intr.width))
    uv = np.stack([cols.ravel() + 0.5, rows.ravel() + 0.5], axis=1)

    def hit(uv: np.ndarray) -> np.ndarray:
        d = intr.pixel_rays(uv) @ pose.R
        return pose.center + (-pose.center[2] / d[:, 2])[:, None] * d

    xmin, ymin = scene.vertices[:, :2].min(axis=0)
    nx, ny = (np.round(np.ptp(scene.vertices[:, :2], axis=0) / 0.001) + 1).astype(int)

    def patch_at(x: np.ndarray) -> np.ndarray:
        """Patch of the chart's grid vertex (1 mm, axis-aligned) nearest to x."""
        ix = np.round((x[:, 0] - xmin) / 0.001).astype(int)
        iy = np.round((x[:, 1] - ymin) / 0.001).astype(int)
        ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        return np.where(ok, scene.patch[np.where(ok, ix * ny + iy, 0)], -1)

    x = hit(uv)
    patch = patch_at(x)
    inside = patch >= 0
    for du, dv in [(-2, 0), (2, 0), (0, -2), (0, 2)]:
        inside &= patch_at(hit(uv + [du, dv])) == patch
    refl = np.where(inside[:, None], colorchecker_reflectances()[1][patch], 0.0)
    s = forward.shading(x, np.tile([0.0, 0.0, 1.0], (len(x), 1)), cam.light.position)
    resp = forward.response_matrix(cam.sensitivity, cam.light.spd())
    y = forward.render_values(refl, s, resp)
    return y.reshape(intr.height, intr.width, 3), inside.reshape(intr.height, intr.width)


def test_render_of_plane_matches_analytic_model_and_dng_decodes_to_it(
    chart: Scene, tmp_path: Path
) -> None:
    cam = _camera(chart, np.array([0.06, -0.03, HEIGHT_M]))
    expect, inside = _analytic(cam, chart)
    assert inside.sum() > 2000
    linear = cam.render_linear()
    np.testing.assert_allclose(linear[inside], expect[inside], rtol=1e-5)

    frame = cam.capture(tmp_path, "plane")
    assert frame.paths == (tmp_path / "plane.dng",)
    s = cam.sensor
    gain = s.exposure_s * s.iso / 100
    y = decode(frame.paths[0]).astype(float) / 65535 / gain  # linear values (docs/architecture.md)
    resid = (y - expect)[inside]
    # Unbiased: per-channel mean relative error well under 1 %.
    np.testing.assert_allclose(resid.mean(0) / expect[inside].mean(0), 0.0, atol=3e-3)
    # Noise of the size the sensor model predicts (shot + read), not zero and not more.
    span = s.white_level - s.black_level
    var_dn = expect[inside] * span * gain / (s.gain_e_per_dn * 100 / s.iso) + s.read_noise_dn**2
    sigma = np.sqrt(var_dn.mean(0)) / (span * gain)
    rms = np.sqrt((resid**2).mean(0))
    assert np.all(rms > 0.3 * sigma) and np.all(rms < 1.5 * sigma)
    assert frame.extra["black_level"] == 512 and frame.extra["white_level"] == 16383


def test_saturation_clips_at_white_level(chart: Scene, tmp_path: Path) -> None:
    cam = _camera(chart, np.array([0.0, 0.0, HEIGHT_M]))
    cam.set_exposure(exposure_s=30.0)
    frame = cam.capture(tmp_path, "bright")
    with rawpy.imread(str(frame.paths[0])) as raw:
        assert raw.raw_image.max() == 16383
    assert frame.extra["saturated_fraction"] > 0.1
    with pytest.raises(RigError, match=r"sim\.camera\.exposure_s' is 0\.0 .* > 0"):
        cam.set_exposure(exposure_s=0.0)


def test_same_seed_same_bytes(chart: Scene, tmp_path: Path) -> None:
    paths = []
    for k in range(2):
        cam = _camera(chart, np.array([0.05, 0.0, HEIGHT_M]))
        paths.append(cam.capture(tmp_path / str(k), "f").paths[0])
    assert paths[0].read_bytes() == paths[1].read_bytes()
    other = cam.capture(tmp_path, "g").paths[0]  # another frame: fresh noise
    assert other.read_bytes() != paths[0].read_bytes()
    reseeded = SimCamera(chart, cam.light, None, SENSOR, seed=2)
    reseeded.set_pose(cam.pose)
    assert reseeded.capture(tmp_path / "2", "f").paths[0].read_bytes() != paths[0].read_bytes()


def test_shadow_where_light_is_occluded(tmp_path: Path) -> None:
    from tests.reconstruct.model.test_forward import plane

    ground, gf = plane(0.3, 0.0, n=8)
    block, bf = plane(0.04, 0.08)
    v = np.vstack([ground, block])
    f = np.vstack([gf, bf + len(ground)])
    refl = np.full((len(v), 31), 0.6)
    scene = Scene("shadow", v, f, refl, np.arange(400.0, 701.0, 10.0), np.full(len(v), -1))
    light = np.array([0.15, 0.0, 0.3])
    cam = _camera(scene, light)
    y = decode(cam.capture(tmp_path, "s").paths[0]).astype(float) / 65535 / 2.5
    # Where the blocker's centre throws its shadow on the ground, and its mirror point.
    k = light[2] / (light[2] - 0.08)
    shadow = light + k * (np.array([0.0, 0.0, 0.08]) - light)
    mirror = shadow * [-1, -1, 0]
    (su, sv), (mu, mv) = cam.intrinsics.project_camera(
        cam.pose.to_camera(np.stack([shadow, mirror]))
    )
    dark = y[int(sv) - 2 : int(sv) + 3, int(su) - 2 : int(su) + 3]
    lit = y[int(mv) - 2 : int(mv) + 3, int(mu) - 2 : int(mu) + 3]
    assert dark.mean() < 0.01 * lit.mean()
    assert lit.min() > 0.05
