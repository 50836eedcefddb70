"""The joint optimisation's settings (the ``optimise:`` section of a reconstruct config) and
its input, the reconstruction's first half."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from calibration.basis import SpectralBasis
from calibration.estimation import DEFAULT_SMOOTHNESS
from calibration.prior import Regulariser
from core.config import bounded, from_mapping
from reconstruct.optimise.cost import Robust
from reconstruct.optimise.pooling import PoolingSettings
from reconstruct.optimise.problem import Frames, Rig
from reconstruct.optimise.solver import SolverSettings

# "offset": one shared camera-plate offset (bulb); "free": one position per view (projector);
# "fixed": one position per view held at the initial positions (the paper fixes the projector
# poses; free lights drift because the light distance trades against the reflectance scale).
SettingsLightMode = Literal["offset", "free", "fixed"]


@dataclass
class OptimiseSettings:
    """Settings of the joint optimisation (the ``optimise:`` section of a reconstruct config)."""

    # γ1 (spectral) is 3, not the paper's 0.01: with 2 illuminations × 3 channels < N_b basis
    # weights the spectral term must carry the null space (the far red under white LEDs).
    # γ2 (photometric) is 4, not 2: where a thin part's normals end off, only the vertex's
    # neighbours can correct its mis-scaled reflectance (docs/architecture.md, Cost).
    gamma: tuple[float, float, float] = bounded((3.0, 4.0, 0.01), min=0.0, max=1e9)
    # What γ1 weighs (calibration.prior): the paper's spectral smoothness (eq. 14), or the
    # training reflectances' shape prior, which lowers the 2-D floor but not, yet, the joint
    # solve's colour error (bench/README.md, spectral_prior).
    spectral_prior: Regulariser = "smoothness"
    # The rendering term is evaluated in 8-bit units (image value × 255), as in the paper's
    # implementation: in 0..1 linear units the paper's γ over-regularise by 255² (the light
    # distance then trades against the reflectance scale; light z off by centimetres).
    rendering_scale: float = bounded(255.0, above=0.0, max=1e9)
    light_mode: SettingsLightMode = "offset"
    # A Cauchy loss on each observation's RGB error: observations the model cannot explain
    # (highlights, silhouette taps, shadow-edge misses) stop pulling shape, light and colour.
    robust: Robust = "cauchy"
    # linear image units: RGB error where the robust loss bends
    robust_scale: float = bounded(0.02, above=0.0, max=1e3)
    # Gloss: observations whose difference from the vertex's diffuse value has the lamps' own
    # colour (a neutral highlight) beyond ``highlight_tolerance`` × that value, near the mirror
    # direction, are down-weighted in the rendering term and the starting estimate
    # (reconstruct/optimise/highlights.py). Off: it costs colour on scenes without gloss
    # (bench/README.md, "Real optics").
    highlights: bool = False
    highlight_tolerance: float = bounded(0.1, above=0.0, max=1e3)
    # the lobe's reach: the allowance doubles at this angle between normal and half-vector
    highlight_lobe_deg: float = bounded(25.0, above=0.0, max=180.0)
    # Gloss, modelled: before each joint stage a neutral GGX lobe (one per object) is fitted to
    # the diffuse model's residual and its highlight taken off the observations
    # (reconstruct/optimise/gloss.py); ``none``: a Lambertian object.
    gloss: Literal["none", "fit"] = "none"
    # The final colour stage: the reflectance alone at the final shape and light, each
    # observation weighed by 1 / (1 + (g / tap_gradient_scale)²), g the image's relative
    # gradient at its tap (per pixel): a tap on a paint, shadow or silhouette edge reads a mix
    # of what its pixel covers (bench/README.md, "Edge taps"). 0: no such stage unless gloss.
    tap_gradient_scale: float = bounded(0.3, min=0.0, max=1e6)
    outer_iterations: int = bounded(3, min=0, max=1000)
    light_iterations: int = bounded(15, min=0, max=10_000)
    # Each joint stage does most of its work in its first few steps; the shadow and
    # observation rebuild between stages moves the problem more than later steps would.
    joint_iterations: int = bounded(8, min=0, max=10_000)
    # Vertices move along their normals (fixed per joint stage), not in 3-D as in the paper:
    # shading and the geometric term are blind to tangential motion, along which they drift.
    optimise_positions: bool = True
    # Runaway guard: per joint stage a vertex moves at most ``max_step_edges`` of its local mean
    # edge length, and at most ``max_total_edges`` (initial mesh's edges) from the initial mesh;
    # vertices seen (at non-grazing angles) from fewer than ``min_views`` views do not follow
    # their own data but the surface around them (``mesh.carried_along``). One or two
    # corrupted views otherwise pull silhouette vertices into spikes.
    # The stage cap is as wide as the total one: a tighter cap clamps many vertices of a
    # dense start from the first step, and LM's steps then no longer fit the clamped problem.
    max_step_edges: float = bounded(2.0, min=0.0, max=1e6)
    max_total_edges: float = bounded(2.0, min=0.0, max=1e6)
    min_views: int = bounded(2, min=0, max=10_000)
    # Coarse to fine: the rendering term's disparity cue reaches about as far as the blur of
    # the images it samples, so a start a few pixels off is out of reach at full resolution.
    # With ``coarse_blur_px`` > 0 the light stage and then ``coarse_levels`` joint stages sample
    # images blurred by σ = coarse_blur_px, coarse_blur_px / 2, … (pixels at the median view's
    # scale; nearer views are blurred more, so every view blurs the same patch of surface),
    # and a vertex may move up to σ per coarse stage (the total limit grows by the same);
    # the ``outer_iterations`` full-resolution stages follow.
    coarse_blur_px: float = bounded(0.0, min=0.0, max=1000.0)
    coarse_levels: int = bounded(2, min=0, max=20)
    # stop when no vertex moved more than this × mean edge length
    settle_position: float = bounded(0.02, min=0.0, max=1e6)
    settle_light_m: float = bounded(1e-4, min=0.0, max=1e6)
    sigma_chroma: float = bounded(0.03, min=0.0, max=1e6)
    sigma_intensity: float = bounded(0.25, min=0.0, max=1e6)
    # the 2-D estimate the solve starts from
    init_smoothness: float = bounded(DEFAULT_SMOOTHNESS, min=0.0, max=1e9)
    margin_px: float = bounded(1.0, min=0.0, max=10_000.0)
    # Observations seen at grazing angles (cos(normal, view) below this) are dropped: their
    # bilinear taps straddle the silhouette and mix in the background.
    min_view_cos: float = bounded(0.3, min=-1.0, max=1.0)
    shadow_eps: float = bounded(1e-4, min=0.0, max=1.0)
    solver: SolverSettings = field(default_factory=SolverSettings)
    # After the solve, each vertex's basis weights along the directions the stacked responses
    # see at less than this share of their strongest are re-set by the spectral regulariser
    # alone (calibration/unseen.py): there the fit follows the images' noise (bench/README.md,
    # "Weakly seen directions"). 0: the data's, however weak.
    weakly_seen_share: float = bounded(0.003, min=0.0, max=1.0)
    # Vertices the solve left folded take the colour of settled neighbours that agree on one
    # paint (reconstruct/optimise/pooling.py; ``max_fold_deg: 0`` keeps every vertex's own).
    pooling: PoolingSettings = field(default_factory=PoolingSettings)

    @property
    def glossy(self) -> bool:
        """The object is declared glossy (gloss fitted or highlights down-weighted): the front
        end leaves highlights out of fusion too (``reconstruct.run.front``)."""
        return self.gloss != "none" or self.highlights

    @classmethod
    def from_mapping(
        cls, conf: Mapping[str, Any] | None, where: str = "config"
    ) -> OptimiseSettings:
        """Settings from the config's ``optimise`` section; errors name ``where`` and the key."""
        return from_mapping(cls, conf, where, "optimise")


@dataclass
class OptimiseInput:
    """The reconstruction's first half, as the optimiser needs it.

    ``visibility`` (N, N_views) bool: V(i) per view. Observed colours come from
    ``frames.images`` (sampled at the projections) or, without images, from ``observed``
    (N, F, 3), NaN where not observed. ``reflectance_upper``: the reflectance's upper bound,
    1 where its scale is absolute, inf where the poses have no metric scale (the reflectance is
    then known only up to a factor); its lower bound is always 0. ``light_radius``: the bulb's
    radius in the poses' units (0: a point light; :mod:`.problem_setup` says what it changes).
    """

    vertices: np.ndarray
    faces: np.ndarray
    visibility: np.ndarray
    rig: Rig
    frames: Frames
    basis: SpectralBasis
    observed: np.ndarray | None = None
    initial_light: np.ndarray | None = None
    initial_alpha: np.ndarray | None = None
    reflectance_upper: float = 1.0
    light_radius: float = 0.0
