"""Real optics in the external-renderer benchmark (issue 33): the sphere bulb against the point
light it replaces (far field, grazing light, soft shadows), the GGX gloss lobe, the lens
fall-off gain and the cache keys of every switch."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from tiny_scene import TINY

pytest.importorskip("mitsuba")

from bench.external_optics import PRESETS, Optics, falloff_gain, sphere_radiance
from bench.external_render import ShadingRenderer
from reconstruct.model.camera import Intrinsics, Pose
from tests.plates import join, rectangle

BULB = PRESETS["bulb"]


def plate_points(intr: Intrinsics, pose: Pose) -> np.ndarray:
    """The world point of z = 0 each pixel centre sees, (H, W, 3)."""
    v, u = np.mgrid[0 : intr.height, 0 : intr.width] + 0.5
    rays = pose.R.T @ intr.pixel_rays(np.stack([u.ravel(), v.ravel()], 1)).T
    c = pose.center
    return (c + (rays * (-c[2] / rays[2])).T).reshape(intr.height, intr.width, 3)


def point_irradiance(points: np.ndarray, light: np.ndarray) -> np.ndarray:
    """cos θ / d² of a point light of intensity π on a white Lambertian plate facing +z."""
    d = light - points
    dist = np.linalg.norm(d, axis=-1)
    return np.clip(d[..., 2], 0, None) / dist**3


PLATE = rectangle((-0.1, -0.1, 0.0), (0.2, 0.0, 0.0), (0.0, 0.2, 0.0), 41)  # facing +z
INTR = Intrinsics.pinhole(64, 48, 60.0)
POSE = Pose.look_at(np.array([0.03, -0.02, 0.3]), np.zeros(3), up=(0.0, 1.0, 0.0))


def test_sphere_of_equal_power_is_the_point_light_seen_from_far() -> None:
    intensity, radius = np.pi, 0.03
    radiance = sphere_radiance(intensity, radius)
    # power: a Lambertian sphere emits π L per unit area over 4π r², the point 4π I
    np.testing.assert_allclose(np.pi * radiance * 4 * np.pi * radius**2, 4 * np.pi * intensity)
    v, f, patch = join(PLATE)
    point = ShadingRenderer(v, f, patch, INTR, spp=16)
    bulb = ShadingRenderer(v, f, patch, INTR, spp=16, optics=BULB)
    points = plate_points(INTR, POSE)
    inside = np.all(np.abs(points[..., :2]) < 0.09, axis=-1)
    far = np.array([0.2, 0.1, 2.0])
    analytic = point_irradiance(points, far)
    np.testing.assert_allclose(point.render(POSE, far)[0][inside], analytic[inside], rtol=0.01)
    np.testing.assert_allclose(bulb.render(POSE, far)[0][inside], analytic[inside], rtol=0.01)
    # near, it still is wherever the whole sphere is above the surface's horizon (a uniform
    # sphere's irradiance is its centre's, Φ cos θ / 4π d²); both box-filtered alike here
    # (mean over the plate: 16 samples of a sphere this close leave a few % noise per pixel)
    near = np.array([0.02, 0.0, 0.12])
    sphere, centre = bulb.render(POSE, near)[0][inside], point.render(POSE, near)[0][inside]
    np.testing.assert_allclose(sphere.mean(), centre.mean(), rtol=0.01)
    assert np.corrcoef(sphere, centre)[0, 1] > 0.98


def test_bulb_reaching_over_the_horizon_lights_what_the_point_cannot() -> None:
    v, f, patch = join(PLATE)
    light = np.array([0.15, 0.0, -0.01])  # centre just below the plate's plane, beside it
    point = ShadingRenderer(v, f, patch, INTR, spp=16).render(POSE, light)[0]
    bulb = ShadingRenderer(v, f, patch, INTR, spp=64, optics=BULB).render(POSE, light)[0]
    points = plate_points(INTR, POSE)
    inside = np.all(np.abs(points[..., :2]) < 0.09, axis=-1)
    assert np.all(point[inside] == 0)  # the point light is behind the plate
    near, far = inside & (points[..., 0] > 0.06), inside & (points[..., 0] < -0.06)
    # the 2 cm cap above the horizon lights the plate, most where it is nearest
    assert bulb[near].mean() > 2 * bulb[far].mean() > 0


def test_bulb_casts_a_penumbra_the_point_light_does_not() -> None:
    wall = rectangle((0.0, -0.1, 0.0), (0.0, 0.2, 0.0), (0.0, 0.0, 0.05), 21)  # 5 cm high
    v, f, patch = join(PLATE, wall)
    intr = Intrinsics.pinhole(128, 96, 160.0)
    pose = Pose.look_at(np.array([0.0, 0.0, 0.3]), np.zeros(3), up=(0.0, 1.0, 0.0))
    light = np.array([0.05, 0.0, 0.2])  # shadow edge of the point light at x = -1/60 m
    points = plate_points(intr, pose)
    lit = point_irradiance(points, light)
    ratios = []
    for optics in (Optics(), BULB):
        shading = ShadingRenderer(v, f, patch, intr, spp=64, optics=optics).render(pose, light)
        row = np.abs(points[..., 1]) < 0.005
        left = row & (points[..., 0] < -0.003) & (points[..., 0] > -0.08)
        ratios.append((shading[0][left] / lit[left], points[..., 0][left]))
    (hard, x), (soft, _) = ratios
    np.testing.assert_allclose(hard[x < -0.02], 1.0, rtol=0.02)  # lit beyond the edge
    assert np.all(hard[(x > -0.013) & (x < -0.003)] < 0.01)  # in the umbra
    # the sphere's edge rays from its far and near side fall at x = -0.0267 and -0.0067:
    # partial light in between, where the point light's shadow is all or nothing
    partial = (soft > 0.1) & (soft < 0.9)
    assert np.all(partial[(x > -0.022) & (x < -0.011)])
    assert np.mean((hard > 0.1) & (hard < 0.9)) < np.mean(partial) / 4


def test_gloss_adds_a_highlight_at_the_mirror_point_and_little_elsewhere() -> None:
    v, f, patch = join(PLATE)
    light = POSE.light_position(np.array([0.05, 0.0, 0.0]))
    glossy = ShadingRenderer(v, f, patch, INTR, spp=64, optics=PRESETS["gloss"])
    shading = glossy.render(POSE, light)
    assert glossy.n_images == 2 and shading.shape[0] == 2
    diffuse, specular = shading[0], shading[1]
    np.testing.assert_allclose(
        diffuse, ShadingRenderer(v, f, patch, INTR, spp=64).render(POSE, light)[0], atol=1e-6
    )
    points = plate_points(INTR, POSE)
    inside = np.all(np.abs(points[..., :2]) < 0.09, axis=-1)
    to_cam = POSE.center - points
    to_light = light - points
    half = to_cam / np.linalg.norm(to_cam, axis=-1, keepdims=True)
    half = half + to_light / np.linalg.norm(to_light, axis=-1, keepdims=True)
    tilt = np.degrees(np.arccos(half[..., 2] / np.linalg.norm(half, axis=-1)))
    mirror = np.unravel_index(np.argmin(np.where(inside, tilt, 99)), tilt.shape)
    peak = np.unravel_index(np.argmax(np.where(inside, specular, 0)), tilt.shape)
    assert np.hypot(*np.subtract(mirror, peak)) <= 3  # the highlight is where the mirror is
    ratio = specular[inside] / diffuse[inside]
    # GGX α 0.2 at its peak: F D / 4 = 0.04 / (4 π α²) ≈ 0.08 against the white's 1/π
    assert 0.15 < ratio.max() < 0.35
    assert np.all(ratio[tilt[inside] > 15] < 0.05)  # off the lobe: within its few %


def test_falloff_gain_is_cos4_times_the_lens_polynomial() -> None:
    intr = Intrinsics.pinhole(80, 60, 70.0)
    gain = falloff_gain(intr, PRESETS["falloff"])
    corner = np.hypot(40 - 0.5, 30 - 0.5) / 70.0  # tan θ of the corner pixel's centre
    np.testing.assert_allclose(gain[0, 0], np.cos(np.arctan(corner)) ** 4)
    np.testing.assert_allclose(gain[29:31, 39:41], 1.0, atol=1e-3)
    np.testing.assert_allclose(gain, gain[::-1, ::-1])
    k = (-0.5, 0.25, -0.05)
    lens = falloff_gain(intr, replace(PRESETS["falloff"], lens_k=k))
    r2 = (39.5**2 + 29.5**2) / (40.0**2 + 30.0**2)
    np.testing.assert_allclose(lens[0, 0] / gain[0, 0], 1 + k[0] * r2 + k[1] * r2**2 + k[2] * r2**3)
    assert np.all(falloff_gain(intr, Optics()) == 1.0)


def test_cache_key_changes_with_every_rendered_switch(tmp_path: Path) -> None:
    v, f, patch = join(PLATE)
    keys = {
        name: ShadingRenderer(v, f, patch, INTR, optics=optics, cache=tmp_path)._key
        for name, optics in PRESETS.items()
    }
    # bulb and gloss change the renders; fall-off is a gain after them (no new renders)
    assert len({keys[n] for n in ("ideal", "bulb", "gloss", "real")}) == 4
    assert keys["falloff"] == keys["lens"] == keys["ideal"]
    assert keys["real"] == keys["real-lens"]
    assert Optics(bulb_radius_m=0.02).render_key() != BULB.render_key()


def test_sessions_carry_the_gloss_and_the_falloff_into_their_raws(
    shared_data: Path, tmp_path: Path
) -> None:
    from bench.external_session import Size, build_session
    from reconstruct.frames.decode import decode_raw

    spec = replace(TINY, distance_factors=(1.0,))
    size = Size(width=64, height=48, focal_px=60.0, views=2, spp=8)
    frames = {}
    for name in ("ideal", "lens", "real"):
        session = build_session(
            spec, replace(size, optics=PRESETS[name]), tmp_path / name, shared_data, tmp_path / "c"
        )
        raw = sorted((session / "raw").glob("*_L1.dng"))[0]
        frames[name] = decode_raw(raw, "linear", 0.98)[0].sum(axis=-1)
    # fall-off reuses the ideal renders (same cache files) and darkens by its gain
    assert len(list((tmp_path / "c").glob("*.npz"))) == 2 * 2  # ideal's and real's, 2 views
    gain = falloff_gain(Intrinsics.pinhole(64, 48, 60.0), PRESETS["lens"])
    seen = frames["ideal"] > 0.05 * frames["ideal"].max()
    ratio = frames["lens"][seen].sum() / (gain * frames["ideal"])[seen].sum()
    np.testing.assert_allclose(ratio, 1.0, atol=0.02)
    assert gain[seen].min() < 0.9  # the object reaches where the fall-off is strong
    # all together: the fall-off as above, the gloss a few % brighter on the whole and
    # highlights on the surfaces that mirror the bulb into the lens
    real_gain = falloff_gain(Intrinsics.pinhole(64, 48, 60.0), PRESETS["real"])
    real = frames["real"][seen] / (real_gain * frames["ideal"])[seen]
    assert 1.0 < np.median(real) < 1.08
    assert np.percentile(real, 99) > 1.2


def test_flat_field_step_on_rendered_white_cards_recovers_the_lens_and_decode_removes_it(
    shared_data: Path, tmp_path: Path
) -> None:
    """`--flat-field`: the wizard's flat-field step photographs white cards Mitsuba renders
    through the lens (matte, under the scene's bulb); the fitted gain is the lens's, the
    session names it, decode divides; the profile gives the bulb's size."""
    from bench.external_session import FLAT_FIELD_NAME, Size, build_session
    from calibration.store import CalibrationStore
    from core.session import Session
    from reconstruct.frames.decode import session_flat_field

    spec = TINY
    optics = PRESETS["real-lens"]
    size = Size(width=64, height=48, focal_px=112.0, views=2, optics=optics, flat_field=True)
    session_dir = build_session(spec, size, tmp_path, shared_data, tmp_path / "cache")
    _, flat = CalibrationStore(tmp_path / "store").flat_field(FLAT_FIELD_NAME, None)
    truth = falloff_gain(Intrinsics.pinhole(64, 48, 112.0), optics)
    assert truth.min() < 0.6  # a strong lens: the corners at under 60 % of the centre
    np.testing.assert_allclose(flat.gain(64, 48), np.repeat(truth[..., None], 3, 2), rtol=0.03)
    session = Session.open(session_dir)
    assert session.info.calibration.flat_field is not None
    assert session.info.calibration.flat_field.entry == FLAT_FIELD_NAME
    divider, files = session_flat_field(session)
    assert divider is not None and files  # decode divides every frame by it
    assert session.info.light_diameter_m == pytest.approx(2 * optics.bulb_radius_m)
