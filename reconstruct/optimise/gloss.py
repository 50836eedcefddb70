"""A neutral gloss lobe fitted to what the diffuse model leaves (``optimise.gloss: fit``).

The dichromatic model: a glossy surface adds to its diffuse colour a highlight in the lamp's
own colour. Before each joint stage (and a second light stage) one GGX lobe for the whole
object (:func:`reconstruct.model.forward.ggx_lobe`) is fitted to the residual of the diffuse
model at the current shape, reflectance and light: its roughness from :data:`ROUGHNESS`, its
scale (the specular reflectance, ≥ 0) by least squares beside the same lobe in each surface's
own colour (a shading error near the mirror direction, which is not gloss and is left in).
The stage then subtracts its predicted highlight from each observation
(``Weights.observed_offset``), so light and shape are fitted to the diffuse part; inside a
stage the highlight is frozen, as the shadow masks are.

The final colour stage solves the reflectance from the observations as they are, then fits the
lobe against that reflectance and, when it explains a good share of the residual
(:func:`colour_without_gloss`), solves again with it taken off: left in, the gloss would
brighten every colour towards the lamp's. Fitted against a reflectance solved with a lobe
already off, the two trade brightness (a broader, stronger lobe and a darker surface explain
the same pixels); against one solved with none, the lobe is what no reflectance explains.
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
# the share of the residual the lobe must explain to be taken off the colour stage: on a matte
# object it explains a sliver (shading errors near the mirror direction, which a broad lobe
# fits and whose removal would move the colour where they sit); on a glossy one, most of it
COLOUR_EXPLAINED_MIN = 0.1


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
    o = problem.obs
    lamp = problem.rig.responses.sum(axis=2)[o.illumination]  # (M, 3)
    own = state.colours[o.illumination, o.vertex]  # the vertex's diffuse colour (M, 3)
    total = float(np.sum(residual**2))
    best = GlossFit(0.0, ROUGHNESS[0], 0.0, np.zeros_like(residual))
    for alpha in ROUGHNESS:
        lobe = np.where(lit, ggx_lobe(n, to_light, to_eye, alpha) / dist2, 0.0)[cost.obs_pair]
        # the dichromatic split: along the lobe, what has the lamp's colour is gloss; what has
        # the surface's own colour is a shading error the lobe would otherwise absorb
        highlight, shading_error = lobe[:, None] * lamp, lobe[:, None] * own
        scale = _neutral_scale(residual, highlight, shading_error)
        if scale <= 0:
            continue
        explained = 1.0 - float(np.sum((residual - scale * highlight) ** 2)) / max(total, 1e-300)
        if explained > best.explained:
            best = GlossFit(scale, alpha, explained, scale * highlight)
    return best


def _neutral_scale(residual: np.ndarray, neutral: np.ndarray, coloured: np.ndarray) -> float:
    """The scale of ``neutral`` in the least-squares fit of ``residual`` by both regressors
    (M, 3) together; 0 where it comes out negative or the two cannot be told apart."""
    a, b = neutral.ravel(), coloured.ravel()
    gram = np.array([[a @ a, a @ b], [a @ b, b @ b]])
    rhs = np.array([a @ residual.ravel(), b @ residual.ravel()])
    if np.linalg.cond(gram) > 1e8:
        return 0.0
    return max(float(np.linalg.solve(gram, rhs)[0]), 0.0)


def without_gloss(problem: Problem, theta: np.ndarray) -> tuple[Problem, GlossFit]:
    """``problem`` with the fitted lobe's highlight taken off every observation, and the fit."""
    fit = _logged_fit(problem, theta)
    return _taken_off(problem, fit), fit


def colour_without_gloss(problem: Problem, theta: np.ndarray) -> tuple[Problem, GlossFit | None]:
    """For the colour stage: ``problem`` with the lobe's highlight taken off when the lobe
    explains at least :data:`COLOUR_EXPLAINED_MIN` of the residual, and that fit; else
    ``problem`` as it is and None."""
    fit = _logged_fit(problem, theta)
    if fit.explained < COLOUR_EXPLAINED_MIN:
        log.info("gloss: left in for the colour stage, too little of the residual to be gloss")
        return problem, None
    return _taken_off(problem, fit), fit


def _logged_fit(problem: Problem, theta: np.ndarray) -> GlossFit:
    fit = fit_gloss(problem, theta)
    log.info(
        "gloss: specular %.3g, roughness %.2g, %.1f %% of the diffuse residual explained",
        fit.specular, fit.roughness, 100 * fit.explained,
    )
    return fit


def _taken_off(problem: Problem, fit: GlossFit) -> Problem:
    return replace(problem, weights=replace(problem.weights, observed_offset=fit.highlight))
