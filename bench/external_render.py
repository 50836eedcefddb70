"""Per-patch shading images rendered by Mitsuba 3, an independent physically based renderer.

Mitsuba renders RGB, so the spectra are composed outside it, exactly: every patch's *shading*
image is rendered with an indicator reflectance (patch k white, the rest black; three patches
at once in the R, G, B channels of one render) under a white light, with direct illumination
only (``path`` with ``max_depth = 2``), so an image is linear in the indicators and

    camera RGB = Σ_k shading_k · Cᵀ diag(L) ρ_k.

The point light has intensity π, so a Lambertian patch of albedo 1 returns ``cos θ / d²``: the
radiometric scale of the project's own model, computed here by a different renderer (its own
BVH, shadow rays, smooth normals and box-filtered pixel sampling). Renders are cached on disk
(compressed float16), keyed by everything that changes them, so several lamps, cameras and
noise seeds reuse one set.

Real optics (``bench.external_optics``): the point light becomes a sphere emitter with the
same power, and a neutral GGX lobe adds one more image, the *specular* shading (rendered with
the lobe alone, white), returned after the patches' and composed with a white reflectance.
"""

from __future__ import annotations

import glob
import hashlib
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from bench._common import cache_temporary
from bench.external_optics import IDEAL, Optics, sphere_radiance
from core.errors import RigError
from core.install import install_command
from reconstruct.model.camera import Intrinsics, Pose
from reconstruct.model.render import vertex_normals

_STATE: dict[str, Any] = {}
VARIANTS = ("llvm_ad_rgb", "scalar_rgb")
MIN_LLVM = 16  # LLVM 15 cannot select the fminimum Mitsuba 3.9's kernels use on x86


def newest_libllvm() -> str | None:
    """The newest system libLLVM Dr.Jit can use (``apt install libllvm19`` provides one)."""
    found = []
    for path in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/libLLVM*.so*"):
        version = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", Path(path).name)
        if version and int(version.group(1)) >= MIN_LLVM:
            found.append((int(version.group(1)), path))
    return max(found)[1] if found else None


def mitsuba(variant: str | None = None) -> Any:
    """The ``mitsuba`` module with a variant set: ``llvm_ad_rgb`` where libLLVM loads (much
    faster), else ``scalar_rgb``. A missing package is one clear error."""
    if "mi" in _STATE:
        return _STATE["mi"]
    llvm = "DRJIT_LIBLLVM_PATH" in os.environ
    if not llvm:
        found = newest_libllvm()
        if found:
            os.environ["DRJIT_LIBLLVM_PATH"] = found
            llvm = True
    # Without a usable libLLVM, Dr.Jit finds an older one itself and aborts the process
    # (LLVM 15: "cannot select fminimum"), which no `except` catches: scalar only then.
    names = [variant] if variant else [v for v in VARIANTS if llvm or not v.startswith("llvm")]
    try:
        import mitsuba as mi
    except ImportError as exc:
        raise RigError(
            "the external-renderer benchmark needs Mitsuba 3 (not installed)",
            install_command("external"),
        ) from exc
    for name in names:
        try:
            mi.set_variant(name)
            mi.load_dict({"type": "diffuse"})  # a JIT variant fails here without libLLVM
        except Exception:
            continue
        _STATE["mi"] = mi
        return mi
    raise RigError(f"Mitsuba variant {variant or 'llvm_ad_rgb/scalar_rgb'} does not run here")


def _to_world(mi: Any, pose: Pose) -> Any:
    """Mitsuba's camera-to-world for our world->camera pose (camera y down, z forward)."""
    c = pose.center
    return mi.ScalarTransform4f().look_at(
        origin=[float(x) for x in c],
        target=[float(x) for x in c + pose.R[2]],
        up=[float(x) for x in -pose.R[1]],
    )


class ShadingRenderer:
    """Renders per-patch shading images of one painted mesh (a patch index per vertex)."""

    def __init__(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        patch: np.ndarray,
        intrinsics: Intrinsics,
        spp: int = 16,
        cache: Path | None = None,
        variant: str | None = None,
        optics: Optics = IDEAL,
    ) -> None:
        self.mi = mi = mitsuba(variant)
        self.n_patches = int(patch.max()) + 1
        self.patch = np.asarray(patch)
        self.intrinsics = intrinsics
        self.spp = int(spp)
        self.cache = cache
        self.optics = optics
        fx, fy, cx, cy = (float(p) for p in intrinsics.K[[0, 1, 0, 1], [0, 1, 2, 2]])
        if (
            abs(fx - fy) > 1e-9
            or abs(cx - intrinsics.width / 2) > 1e-9
            or abs(cy - intrinsics.height / 2) > 1e-9
            or np.any(intrinsics.distortion())
        ):
            raise RigError("the external renderer takes centred square-pixel pinholes only")
        self._key = hashlib.sha1(
            b"".join(
                np.ascontiguousarray(a).tobytes()
                for a in (vertices.astype(np.float64), faces.astype(np.int64), self.patch)
            )
            + f"{intrinsics.width}x{intrinsics.height}f{fx}s{spp}{mi.variant()}".encode()
            + optics.render_key().encode()
        ).hexdigest()[:16]
        diffuse = {
            "type": "diffuse",
            "reflectance": {"type": "mesh_attribute", "name": "vertex_color"},
        }
        self._meshes = {False: self._mesh(vertices, faces, diffuse)}
        if optics.gloss_reflectance > 0:
            # the lobe alone, Fresnel of a dielectric (k = 0): added to the diffuse shading,
            # which stays the true albedo (roughplastic cannot take a per-vertex albedo)
            lobe = {
                "type": "roughconductor",
                "distribution": "ggx",
                "alpha": optics.gloss_alpha,
                "eta": optics.gloss_ior,
                "k": 0.0,
            }
            self._meshes[True] = self._mesh(vertices, faces, lobe)
        fov = float(np.degrees(2.0 * np.arctan(intrinsics.width / (2.0 * fx))))
        self._base = {
            "type": "scene",
            "integrator": {"type": "direct", "hide_emitters": True},
            "sensor": {
                "type": "perspective",
                "fov": fov,
                "fov_axis": "x",
                "near_clip": 1e-3,
                "to_world": mi.ScalarTransform4f(),
                "film": {
                    "type": "hdrfilm",
                    "width": intrinsics.width,
                    "height": intrinsics.height,
                    "rfilter": {"type": "box"},
                    "pixel_format": "rgb",
                },
                "sampler": {"type": "independent", "sample_count": self.spp},
            },
        }
        self._scenes: dict[tuple[str, bool], Any] = {}

    def _mesh(self, vertices: np.ndarray, faces: np.ndarray, bsdf: dict[str, Any]) -> Any:
        """The object as a Mitsuba mesh with ``bsdf`` and a (zero) vertex colour attribute."""
        mi = self.mi
        props = mi.Properties()
        props["bsdf"] = mi.load_dict(bsdf)
        mesh = mi.Mesh("object", len(vertices), len(faces), props=props, has_vertex_normals=True)
        mesh.add_attribute("vertex_color", 3, np.zeros(3 * len(vertices), dtype=np.float32))
        params = mi.traverse(mesh)
        params["vertex_positions"] = np.ravel(vertices).astype(np.float32)
        params["faces"] = np.ravel(faces).astype(np.uint32)
        # smooth shading normals computed here: Mitsuba's own normal kernel needs an LLVM
        # newer than 15 on x86, and the project's sim shades with area-weighted normals too
        params["vertex_normals"] = np.ravel(vertex_normals(vertices, faces)).astype(np.float32)
        params.update()
        return mesh

    def _light(self) -> dict[str, Any]:
        """The bulb: a point light of intensity π, or a sphere emitter of the same power."""
        radius = self.optics.bulb_radius_m
        if radius <= 0:
            return {
                "type": "point",
                "position": [0.0, 0.0, 1.0],
                "intensity": {"type": "rgb", "value": [np.pi] * 3},
            }
        radiance = sphere_radiance(np.pi, radius)
        return {
            "type": "sphere",
            "center": [0.0, 0.0, 1.0],
            "radius": radius,
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}},
        }

    def _scene(self, kind: str, gloss: bool) -> Any:
        """The scene with the bulb (``lit``) or a uniform white environment (``ambient``),
        the object diffuse or (``gloss``) its specular lobe alone."""
        if (kind, gloss) not in self._scenes:
            emitter = (
                self._light()
                if kind == "lit"
                else {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
            )
            self._scenes[kind, gloss] = self.mi.load_dict(
                {**self._base, "object": self._meshes[gloss], "emitter": emitter}
            )
        return self._scenes[kind, gloss]

    def _posed(
        self, pose: Pose, light_position: np.ndarray | None, gloss: bool = False
    ) -> tuple[Any, Any]:
        """The lit (or ambient) scene and its parameters with camera and light placed."""
        scene = self._scene("ambient" if light_position is None else "lit", gloss)
        params = self.mi.traverse(scene)
        params["sensor.to_world"] = _to_world(self.mi, pose)
        if light_position is not None:
            position = [float(x) for x in light_position]
            if self.optics.bulb_radius_m > 0:
                params["emitter.to_world"] = (
                    self.mi.ScalarTransform4f().translate(position).scale(self.optics.bulb_radius_m)
                )
            else:
                params["emitter.position"] = position
        return scene, params

    def _indicators(self, chunk: int) -> np.ndarray:
        """Vertex colours with patches 3·chunk, 3·chunk+1, 3·chunk+2 in R, G, B."""
        col = np.zeros((len(self.patch), 3), dtype=np.float32)
        for c in range(3):
            col[self.patch == 3 * chunk + c, c] = 1.0
        return col

    @property
    def n_images(self) -> int:
        """Shading images per render: one per patch, and the specular one with gloss."""
        return self.n_patches + int(self.optics.gloss_reflectance > 0)

    def render(self, pose: Pose, light_position: np.ndarray | None) -> np.ndarray:
        """Shading of every patch (and, with gloss, the specular shading last),
        (n_images, H, W) float32: under the bulb at ``light_position`` (world, metres), or,
        with None, under a uniform unit-radiance environment (ambient light, occlusion
        included)."""
        key = hashlib.sha1(
            np.ascontiguousarray(np.concatenate([pose.R.ravel(), pose.t])).tobytes()
            + (
                b"ambient"
                if light_position is None
                else np.asarray(light_position, float).tobytes()
            )
        ).hexdigest()[:16]
        path = None if self.cache is None else self.cache / f"{self._key}_{key}.npz"
        if path is not None and path.is_file():
            return np.load(path)["shading"].astype(np.float32)
        scene, params = self._posed(pose, light_position)
        chunks = -(-self.n_patches // 3)
        out = np.zeros((3 * chunks, self.intrinsics.height, self.intrinsics.width), np.float32)
        for j in range(chunks):
            params["object.vertex_color"] = np.ravel(self._indicators(j))
            params.update()
            img = np.asarray(self.mi.render(scene, spp=self.spp, seed=j), dtype=np.float32)
            out[3 * j : 3 * j + 3] = np.moveaxis(img, 2, 0)
        out = out[: self.n_patches]
        if self.optics.gloss_reflectance > 0:
            scene, params = self._posed(pose, light_position, gloss=True)
            params.update()
            img = np.asarray(self.mi.render(scene, spp=self.spp, seed=chunks), dtype=np.float32)
            out = np.concatenate([out, img[None, ..., 0]])
        # what the cache keeps, so a first run and a run from the cache capture the same frames
        out = out.astype(np.float16).astype(np.float32)
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = cache_temporary(path)
            np.savez_compressed(tmp, shading=out.astype(np.float16))
            tmp.replace(path)
        return out

    def render_white(self, pose: Pose, light_position: np.ndarray | None) -> np.ndarray:
        """One render with every patch white (H, W): the linearity check of the indicators."""
        scene, params = self._posed(pose, light_position)
        params["object.vertex_color"] = np.ones(3 * len(self.patch), dtype=np.float32)
        params.update()
        return np.asarray(self.mi.render(scene, spp=self.spp, seed=0), dtype=np.float32)[..., 0]


def compose(shading: np.ndarray, patch_rgb: np.ndarray) -> np.ndarray:
    """Camera RGB (H, W, 3) = Σ_k shading_k · rgb_k, with ``patch_rgb`` (K, 3) the
    ``Cᵀ diag(L) ρ_k`` of each patch."""
    return np.einsum("khw,kc->hwc", shading, patch_rgb, optimize=True)
