"""Synthetic vertex-level scenes for tests and benchmarks of the optimiser.

A bumpy sphere with patches of real reflectances (colour-science training set), cameras on a
ring with a light rigidly offset on the camera plate, rendered with the one forward model at the
exact vertex positions (shadow masks by ray casting) and optionally as images. It needs none of
the capture or front-end stages, so the optimiser can be checked on its own against known truth.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import trimesh

from calibration.basis import SpectralBasis, default_basis
from calibration.defaults import (
    camera_sensitivity,
    cie_illuminant,
    default_illuminations,
    illumination_spd,
    rgbcw_channel_spds,
    training_reflectances,
)
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.forward import render_values, response_matrix, shading
from reconstruct.model.raycast import RayCaster
from reconstruct.model.render import render_image, shade, trace_view
from reconstruct.optimise.mesh import vertex_normals
from reconstruct.optimise.problem import Frames, Rig
from reconstruct.optimise.settings import OptimiseInput


@dataclass
class SyntheticScene:
    vertices: np.ndarray  # true positions
    faces: np.ndarray
    reflectance: np.ndarray  # true (N, N_λ)
    alpha: np.ndarray  # true basis weights (projection of the reflectance)
    light_offset: np.ndarray  # true v (3,)
    rig: Rig
    frames: Frames
    basis: SpectralBasis
    visibility: np.ndarray  # (N, N_views)
    observed: np.ndarray  # (N, F, 3), NaN where not visible
    ambient_images: np.ndarray | None = None  # (N_views, H, W, 3) bulb-off frames (room light)

    def input(self, vertices: np.ndarray | None = None, images: bool = False) -> OptimiseInput:
        """Optimiser input starting from ``vertices`` (default: the truth)."""
        x = self.vertices if vertices is None else vertices
        return OptimiseInput(
            vertices=x,
            faces=self.faces,
            visibility=self.visibility,
            rig=self.rig,
            frames=self.frames,
            basis=self.basis,
            observed=None if images else self.observed,
        )


def default_responses(illuminations: Sequence[str]) -> np.ndarray:
    """(K, 3, N_λ) response matrices of the built-in camera under the built-in bulb's named
    illuminations — what the synthetic scenes are rendered with."""
    cam = camera_sensitivity()
    channels = rgbcw_channel_spds()
    named = default_illuminations()
    return np.stack(
        [response_matrix(cam, illumination_spd(named[k], channels)) for k in illuminations]
    )


def ambient_response(
    illuminations: Sequence[str], level: float, distance_m: float, spd: str = "A"
) -> np.ndarray:
    """(3, N_λ) response of a uniform room light (CIE illuminant ``spd``) whose irradiance is
    ``level`` × the bulb's mean over ``illuminations`` at ``distance_m`` (normal incidence)."""
    channels = rgbcw_channel_spds()
    named = default_illuminations()
    bulb = np.mean([illumination_spd(named[k], channels).sum() for k in illuminations])
    room = cie_illuminant(spd)
    room = room * (level * bulb / distance_m**2 / room.sum())
    return response_matrix(camera_sensitivity(), room)


def bumpy_sphere(
    subdivisions: int = 3, radius: float = 0.05, bumps: float = 0.06
) -> trimesh.Trimesh:
    m = trimesh.creation.icosphere(subdivisions, radius=1.0)
    d = m.vertices
    r = 1.0 + bumps * np.sin(4 * d[:, 0]) * np.sin(3 * d[:, 1] + 1) * np.cos(2 * d[:, 2])
    return trimesh.Trimesh(d * (radius * r)[:, None], m.faces, process=False)


def make_scene(
    subdivisions: int = 3,
    n_views: int = 12,
    illuminations: tuple[str, ...] = ("LED1", "LED2"),
    light_offset: tuple[float, float, float] = (0.06, -0.02, 0.0),
    noise: float = 0.0,
    image_size: tuple[int, int] | None = None,
    seed: int = 0,
    ambient: float = 0.0,
    voronoi: int = 0,
) -> SyntheticScene:
    """A bumpy sphere (radius 5 cm) seen from ``n_views`` cameras 30 cm away, each view under
    every illumination; ``image_size`` (W, H) also renders images for the sampling path.
    ``ambient`` > 0 (images only) adds a uniform illuminant-A room light of that level
    relative to the bulb at the camera distance to every frame, and one bulb-off frame per
    view (``ambient_images``), each with its own noise. The reflectance is 4 patches, or with
    ``voronoi`` > 0 that many Voronoi cells around random directions (more edges: more of the
    rendering term's disparity cue, like the external-renderer scenes' 24 patches)."""
    rng = np.random.default_rng(seed)
    mesh = bumpy_sphere(subdivisions)
    X, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    basis = default_basis()
    d = X / np.linalg.norm(X, axis=1, keepdims=True)
    if voronoi:
        seeds = rng.normal(size=(voronoi, 3))
        label = np.argmax(d @ (seeds / np.linalg.norm(seeds, axis=1, keepdims=True)).T, axis=1)
    else:
        label = (d[:, 0] > 0).astype(int) + 2 * (d[:, 2] > 0.3).astype(int)
    patches = training_reflectances()[rng.choice(214, max(voronoi, 4), replace=False)]
    refl = basis.reconstruct(basis.project(patches[label]))
    alpha = basis.project(refl)
    responses = default_responses(illuminations)
    poses = []
    for k, a in enumerate(np.linspace(0, 2 * np.pi, n_views, endpoint=False)):
        elev = 0.35 * np.sin(3 * a + k)
        eye = 0.3 * np.array([np.cos(a) * np.cos(elev), np.sin(a) * np.cos(elev), np.sin(elev)])
        poses.append(Pose.look_at(eye, np.zeros(3)))
    w, h = image_size or (320, 240)
    intr = [Intrinsics.pinhole(w, h, 1.6 * w)] * n_views
    v = np.asarray(light_offset, dtype=float)
    lights = np.stack([p.light_position(v) for p in poses])
    caster = RayCaster(X, F)
    normals, _ = vertex_normals(X, F)
    vis = np.zeros((len(X), n_views), dtype=bool)
    for c, pose in enumerate(poses):
        facing = np.einsum("ij,ij->i", normals, pose.center - X) > 0
        vis[:, c] = facing & ~caster.occluded(X, pose.center, 1e-5, normals)
    frame_view = np.repeat(np.arange(n_views), len(illuminations))
    frame_ill = np.tile(np.arange(len(illuminations)), n_views)
    observed = np.full((len(X), len(frame_view), 3), np.nan)
    images = None
    if image_size is not None:
        images = np.zeros((len(frame_view), h, w, 3), dtype=np.float32)
    rooms = None
    if images is not None and ambient > 0:
        resp = ambient_response(illuminations, ambient, 0.3)
        rooms = np.stack(
            [
                shade(hits, [(np.ones(len(hits.index)), resp)], refl)
                for hits in (trace_view(caster, intr[c], poses[c]) for c in range(n_views))
            ]
        )
    for f in range(len(frame_view)):
        c, k = int(frame_view[f]), int(frame_ill[f])
        lit = ~caster.occluded(X, lights[c], 1e-5, normals)
        y = render_values(refl, shading(X, normals, lights[c]), responses[k], lit)
        y = y + noise * rng.normal(size=y.shape)
        observed[vis[:, c], f] = y[vis[:, c]]
        if images is not None:
            img, _ = render_image(
                X, F, refl, intr[c], poses[c], lights[c], responses[k], caster=caster
            )
            room = 0.0 if rooms is None else rooms[c]
            images[f] = img + room + noise * rng.normal(size=img.shape)
    ambient_images = None
    if rooms is not None:
        ambient_images = (rooms + noise * rng.normal(size=rooms.shape)).astype(np.float32)
    frames = Frames(frame_view, frame_ill, images)
    return SyntheticScene(
        X,
        F,
        refl,
        alpha,
        v,
        Rig(intr, poses, responses),
        frames,
        basis,
        vis,
        observed,
        ambient_images,
    )


def with_gloss(
    scene: SyntheticScene, reflectance: float = 0.04, alpha: float = 0.2
) -> SyntheticScene:
    """The scene's vertex-level observations plus a neutral GGX lobe (normal-incidence Fresnel
    ``reflectance``, roughness ``alpha``, no shadowing term) in each lamp's own colour: the
    dichromatic model's highlight ``π F D / (4 cos θ_o |p − x|²) · Cᵀ L_k 1`` (the Lambertian
    white's units, where y = cos θ_i / |p − x|² · Cᵀ L_k r)."""
    X = scene.vertices
    normals, _ = vertex_normals(X, scene.faces)
    white = scene.rig.responses.sum(axis=2)
    caster = RayCaster(X, scene.faces)
    observed = scene.observed.copy()
    for f in range(scene.frames.count):
        pose = scene.rig.poses[scene.frames.view[f]]
        light = pose.light_position(scene.light_offset)
        lit = shading(X, normals, light) > 0
        lit &= ~caster.occluded(X, light, 1e-5, normals)
        to_light = light - X
        dist2 = np.einsum("ij,ij->i", to_light, to_light)
        to_eye = pose.center - X
        to_eye /= np.linalg.norm(to_eye, axis=1, keepdims=True)
        half = to_light / np.sqrt(dist2)[:, None] + to_eye
        half /= np.linalg.norm(half, axis=1, keepdims=True)
        cos_h = np.clip(np.einsum("ij,ij->i", normals, half), 1e-3, 1.0)
        cos_o = np.clip(np.einsum("ij,ij->i", normals, to_eye), 1e-3, 1.0)
        tan2 = (1.0 - cos_h**2) / cos_h**2
        ggx = alpha**2 / (np.pi * cos_h**4 * (alpha**2 + tan2) ** 2)
        lobe = np.pi * reflectance * ggx / (4.0 * cos_o * dist2)
        observed[:, f] += (lit * lobe)[:, None] * white[scene.frames.illumination[f]]
    return replace(scene, observed=observed)


def perturb(scene: SyntheticScene, amplitude: float, seed: int = 1) -> np.ndarray:
    """Vertices displaced along their normals by smooth noise of RMS ``amplitude`` (metres)."""
    rng = np.random.default_rng(seed)
    normals, _ = vertex_normals(scene.vertices, scene.faces)
    d = scene.vertices / np.linalg.norm(scene.vertices, axis=1, keepdims=True)
    k = rng.normal(size=(6, 3)) * 3
    ph = rng.uniform(0, 2 * np.pi, 6)
    field = np.sum(np.sin(d @ k.T + ph), axis=1)
    field *= amplitude / np.sqrt(np.mean(field**2))
    return scene.vertices + field[:, None] * normals


def mvs_like_mesh(
    mesh: trimesh.Trimesh,
    points: int = 20000,
    depth: int = 6,
    noise_m: float = 0.0005,
    wave_m: float = 0.001,
    seed: int = 0,
) -> trimesh.Trimesh:
    """An initial mesh of MVS quality made from a true one: surface samples with point noise
    (``noise_m``) and a smooth low-frequency displacement along the normal (RMS ``wave_m``),
    re-meshed by screened Poisson at ``depth`` (smoothing and decimating it)."""
    from reconstruct.initial_mesh.dense.poisson import poisson_mesh

    rng = np.random.default_rng(seed)
    p, face = trimesh.sample.sample_surface(mesh, points, seed=seed)
    n = np.asarray(mesh.face_normals)[face]
    centre = p.mean(axis=0)
    size = float(np.max(np.linalg.norm(p - centre, axis=1)))
    k = rng.normal(size=(6, 3)) * (3.0 / size)
    ph = rng.uniform(0, 2 * np.pi, 6)
    field = np.sum(np.sin((p - centre) @ k.T + ph), axis=1)
    field *= wave_m / np.sqrt(np.mean(field**2))
    p = p + field[:, None] * n + noise_m * rng.normal(size=p.shape)
    return poisson_mesh(p, n, depth=depth, trim=0.0, num_threads=2)
