"""A neutral gloss lobe fitted to what the diffuse model leaves (``optimise.gloss: fit``).

The dichromatic model: a glossy surface adds to its diffuse colour a highlight in the lamp's
own colour. Between joint stages one GGX lobe for the whole object
(:func:`reconstruct.model.forward.ggx_lobe`) is fitted to the residual of the diffuse model at
the current shape, reflectance and light: its roughness from :data:`ROUGHNESS`, its scale (the
specular reflectance, ≥ 0) by least squares. The next stage subtracts its predicted highlight
from each observation (``Weights.observed_offset``), so the diffuse model is fitted to the
diffuse part; inside a stage the highlight is frozen, as the shadow masks are.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from reconstruct.model.forward import ggx_lobe
from reconstruct.optimise.cost import JointCost
from reconstruct.optimise.mesh import vertex_normals
from reconstruct.optimise.problem import Problem

log = logging.getLogger(__name__)

ROUGHNESS = (0.05, 0.1, 0.15, 0.2, 0.3, 0.45, 0.7)  # GGX α tried: mirror-like to satin


@dataclass(frozen=True)
class GlossFit:
    """The lobe that explains the diffuse residual best: ``specular`` its scale (reflectance at
    normal incidence), ``roughness`` its GGX α, ``explained`` the share of the residual's sum
    of squares it removes, ``highlight`` its prediction per observation (M, 3)."""

    specular: float
    roughness: float
    explained: float
    highlight: np.ndarray

    def summary(self) -> dict[str, float]:
        """What the report keeps (the first record of the stage that used it)."""
        return {
            "specular": round(self.specular, 5),
            "roughness": self.roughness,
            "explained": round(self.explained, 4),
        }


def fit_gloss(problem: Problem, theta: np.ndarray) -> GlossFit:
    """Fit the lobe to the residual ``y_obs − y_diffuse`` of every observation at ``theta``."""
    cost = JointCost(problem)
    X, A, light = problem.unpack(theta)
    normals, _ = vertex_normals(X, problem.faces)
    state = cost.render(X, A, light, normals, derivatives=False)
    residual = -state.error
    if problem.weights.observed_offset is not None:  # against the diffuse model alone
        residual = residual - problem.weights.observed_offset
    pv, pc = cost.pair_vertex, cost.pair_view
    x, n = X[pv], normals[pv]
    to_light = problem.light_positions(light)[pc] - x
    dist2 = np.einsum("ij,ij->i", to_light, to_light)
    to_light /= np.sqrt(dist2)[:, None]
    centres = np.stack([pose.center for pose in problem.rig.poses])
    to_eye = centres[pc] - x
    to_eye /= np.linalg.norm(to_eye, axis=1, keepdims=True)
    lit = state.pair_s > 0  # the observation set keeps lit pairs only; the guard is cheap
    lamp = problem.rig.responses.sum(axis=2)[problem.obs.illumination]  # (M, 3)
    total = float(np.sum(residual**2))
    best = GlossFit(0.0, ROUGHNESS[0], 0.0, np.zeros_like(residual))
    for alpha in ROUGHNESS:
        lobe = np.where(lit, ggx_lobe(n, to_light, to_eye, alpha) / dist2, 0.0)
        shape = lobe[cost.obs_pair, None] * lamp
        energy = float(np.sum(shape**2))
        if energy <= 0:
            continue
        scale = max(float(np.sum(residual * shape)) / energy, 0.0)
        explained = 1.0 - float(np.sum((residual - scale * shape) ** 2)) / max(total, 1e-300)
        if explained > best.explained:
            best = GlossFit(scale, alpha, explained, scale * shape)
    return best


def without_gloss(problem: Problem, theta: np.ndarray) -> tuple[Problem, GlossFit]:
    """``problem`` with the fitted lobe's highlight taken off every observation, and the fit."""
    fit = fit_gloss(problem, theta)
    log.info(
        "gloss: specular %.3g, roughness %.2g, %.1f %% of the diffuse residual explained",
        fit.specular, fit.roughness, 100 * fit.explained,
    )
    return replace(problem, weights=replace(problem.weights, observed_offset=fit.highlight)), fit
