"""Real-optics switches of the external-renderer benchmark (issue 33): a bulb with a size, a
neutral specular lobe and lens fall-off, each alone or all together.

The bulb and the gloss are rendered by Mitsuba (a ``sphere`` shape with an ``area`` emitter, a
GGX ``roughconductor`` lobe), never by the project's forward model. Fall-off is the one effect
applied after rendering: it is a sensor-side gain per pixel (``falloff_gain``), applied to the
linear image before the sim camera exposes and writes it as RAW.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from reconstruct.model.camera import Intrinsics


@dataclass(frozen=True)
class Optics:
    """Which real-optics effects a scene is rendered with (all off: the ideal optics)."""

    bulb_radius_m: float = 0.0  # 0: the point light; else a sphere emitter of this radius
    gloss_reflectance: float = 0.0  # specular reflectance at normal incidence (0: Lambertian)
    gloss_alpha: float = 0.2  # GGX roughness of the lobe
    cos4: bool = False  # natural fall-off cos⁴ θ of the angle to the optical axis
    lens_k: tuple[float, float, float] = (0.0, 0.0, 0.0)  # 1 + k1 r² + k2 r⁴ + k3 r⁶

    @property
    def gloss_ior(self) -> float:
        """The dielectric index whose normal-incidence Fresnel reflectance is the gloss's."""
        s = float(np.sqrt(self.gloss_reflectance))
        return (1.0 + s) / (1.0 - s)

    def render_key(self) -> str:
        """What changes Mitsuba's renders (fall-off does not: it is applied afterwards)."""
        key = ""
        if self.bulb_radius_m > 0:
            key += f"bulb{self.bulb_radius_m:g}"
        if self.gloss_reflectance > 0:
            key += f"gloss{self.gloss_reflectance:g}a{self.gloss_alpha:g}"
        return key

    @property
    def has_falloff(self) -> bool:
        return self.cos4 or any(self.lens_k)


IDEAL = Optics()
BULB = Optics(bulb_radius_m=0.03)  # an A19 bulb's diffuser, 6 cm across
GLOSS = Optics(gloss_reflectance=0.04, gloss_alpha=0.2)  # a glaze or varnish (ior 1.5)
FALLOFF = Optics(cos4=True)
# a fast lens wide open: 0.7 of the centre's response at the corner on top of cos⁴
STRONG_LENS = (-0.5, 0.25, -0.05)
REAL = replace(BULB, gloss_reflectance=GLOSS.gloss_reflectance, cos4=True)
PRESETS = {
    "ideal": IDEAL,
    "bulb": BULB,
    "gloss": GLOSS,
    "falloff": FALLOFF,
    "lens": replace(FALLOFF, lens_k=STRONG_LENS),
    "real": REAL,
    "real-lens": replace(REAL, lens_k=STRONG_LENS),
}


def sphere_radiance(intensity: float, radius_m: float) -> float:
    """Radiance of a Lambertian sphere emitter with the point light's power: a sphere of
    radiance L seen from any direction is a disc of area π r², so its intensity is L π r²
    (and its power 4π · that, the point light's 4π I)."""
    return intensity / (np.pi * radius_m**2)


def falloff_gain(intrinsics: Intrinsics, optics: Optics) -> np.ndarray:
    """Per-pixel gain (H, W): cos⁴ of the pixel centre's angle to the optical axis (if on)
    times lensfun's ``pa`` polynomial 1 + k1 r² + k2 r⁴ + k3 r⁶, r = 1 at the image corner."""
    h, w = intrinsics.height, intrinsics.width
    K = intrinsics.K
    v, u = np.mgrid[0:h, 0:w] + 0.5
    x, y = (u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]
    gain = np.ones((h, w))
    if optics.cos4:
        gain /= (1.0 + x**2 + y**2) ** 2  # cos θ = 1 / sqrt(1 + x² + y²)
    if any(optics.lens_k):
        r2 = ((u - w / 2) ** 2 + (v - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
        k1, k2, k3 = optics.lens_k
        gain *= 1.0 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    return gain
