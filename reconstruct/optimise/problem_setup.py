"""The solve's problem at the current estimate: the observation set (visibility, image
bounds, grazing angles, shadows by ray casting to the current lights), its frozen weights, and
the reflectance a solve starts from.

A bulb with a size (``OptimiseInput.light_radius``) is a uniform Lambertian sphere, whose
irradiance on a surface that sees all of it is exactly the point light's at its centre: the
forward model holds wherever the whole bulb is above the surface's horizon and unoccluded. So
observations that see only part of it (the bulb across their horizon, or in a penumbra: a ray
to its centre or to one of :data:`BULB_RIM_RAYS` points on its rim blocked) are left out, as the
point light's shadows are."""

from __future__ import annotations

import logging

import numpy as np

from calibration.basis import SpectralBasis
from calibration.estimation import estimate_reflectance
from calibration.prior import spectral_regulariser
from core.errors import RigError
from reconstruct.model.bulb import rim_points
from reconstruct.model.forward import half_angles, shading
from reconstruct.model.raycast import RayCaster
from reconstruct.optimise.cost import JointCost
from reconstruct.optimise.highlights import highlight_weights
from reconstruct.optimise.mesh import adjacency, edges, vertex_normals
from reconstruct.optimise.problem import LightMode, Observations, Problem, Rig, Weights
from reconstruct.optimise.sampling import sample_pairs, taps_valid
from reconstruct.optimise.settings import OptimiseInput, OptimiseSettings, SettingsLightMode
from reconstruct.optimise.weights import edge_scale, photometric_weights, tap_weights

log = logging.getLogger(__name__)

BULB_RIM_RAYS = 6  # shadow rays to the bulb's rim per observation, besides the one to its centre


def problem_mode(mode: SettingsLightMode) -> LightMode:
    """How a solve parameterises the light: fixed lights are per-view positions kept out of
    the optimised set."""
    return "offset" if mode == "offset" else "free"


def light_positions(rig: Rig, mode: SettingsLightMode, light: np.ndarray) -> np.ndarray:
    light = np.asarray(light, dtype=float).reshape(-1, 3)
    if mode != "offset":
        return light
    return np.stack([pose.light_position(light[0]) for pose in rig.poses])


def rim_hidden(
    caster: RayCaster,
    points: np.ndarray,
    centres: np.ndarray,
    normals: np.ndarray,
    radius: float,
    eps: float,
) -> np.ndarray:
    """Whether any of :data:`BULB_RIM_RAYS` points on the rim of a bulb of ``radius`` at
    ``centres``, as each point sees it, is hidden from it."""
    rim = rim_points(points, centres, radius, BULB_RIM_RAYS)  # (rays, N, 3)
    hidden = caster.occluded(
        np.tile(points, (BULB_RIM_RAYS, 1)),
        rim.reshape(-1, 3),
        eps,
        np.tile(normals, (BULB_RIM_RAYS, 1)),
    )
    return np.asarray(hidden.reshape(BULB_RIM_RAYS, -1).any(axis=0))


def build_problem(
    inp: OptimiseInput,
    X: np.ndarray,
    light: np.ndarray,
    cfg: OptimiseSettings,
    colour_stage: bool = False,
) -> Problem:
    """The observation set and frozen weights at the current estimate (see module doc). For
    the ``colour_stage`` each observation also weighs :func:`tap_weights` (scale
    ``cfg.tap_gradient_scale``): a tap on a paint, shadow or silhouette edge reads a mix of
    what its pixel covers, which the colour should not follow but the shape needs."""
    n = len(X)
    normals, _ = vertex_normals(X, inp.faces)
    P = light_positions(inp.rig, cfg.light_mode, light)
    fr = inp.frames
    if inp.visibility.shape != (n, inp.rig.n_views):
        raise RigError(
            f"visibility has shape {inp.visibility.shape}, expected ({n}, {inp.rig.n_views})",
            "give one column per view of the poses",
        )
    verts, frame_ids = [], []
    for f in range(fr.count):
        vis = np.flatnonzero(inp.visibility[:, fr.view[f]])
        verts.append(vis)
        frame_ids.append(np.full(vis.size, f, dtype=np.int64))
    vertex = np.concatenate(verts) if verts else np.zeros(0, np.int64)
    frame = np.concatenate(frame_ids) if frame_ids else np.zeros(0, np.int64)
    view = fr.view[frame]
    keep = np.ones(vertex.size, dtype=bool)
    observed = np.zeros((vertex.size, 3))
    weigh_taps = colour_stage and cfg.tap_gradient_scale > 0 and inp.observed is None
    taps = np.ones(vertex.size if weigh_taps else 0)  # one factor per candidate observation
    if inp.observed is not None:
        observed = inp.observed[vertex, frame]
        keep &= np.all(np.isfinite(observed), axis=1)
    else:
        assert fr.images is not None and fr.valid is not None
        for c in range(inp.rig.n_views):
            idx = np.flatnonzero(view == c)
            if idx.size == 0:
                continue
            uv = inp.rig.intrinsics[c].project_camera(inp.rig.poses[c].to_camera(X[vertex[idx]]))
            keep[idx] &= taps_valid(fr.valid, frame[idx], uv, cfg.margin_px)
            values, gradient = sample_pairs(
                fr.images, frame[idx], np.arange(idx.size), uv, weigh_taps
            )
            observed[idx] = values
            if weigh_taps:
                taps[idx] = tap_weights(values, gradient, cfg.tap_gradient_scale)
    s = shading(X[vertex], normals[vertex], P[view])
    keep &= s > 0
    if inp.light_radius > 0:  # cos θ > r / d: the whole bulb above the horizon
        keep &= s * np.linalg.norm(P[view] - X[vertex], axis=1) ** 3 > inp.light_radius
    centres = np.stack([pose.center for pose in inp.rig.poses])
    to_cam = centres[view] - X[vertex]
    cos_view = np.einsum("ij,ij->i", normals[vertex], to_cam) / np.linalg.norm(to_cam, axis=1)
    keep &= cos_view >= cfg.min_view_cos
    # Shadow masks: one ray per distinct (vertex, view), shared by that view's illuminations.
    pair = vertex * inp.rig.n_views + view
    upair, inverse = np.unique(pair[keep], return_inverse=True)
    pv, pc = upair // inp.rig.n_views, upair % inp.rig.n_views
    caster = RayCaster(X, inp.faces)
    blocked = caster.occluded(X[pv], P[pc], cfg.shadow_eps, normals[pv])
    if inp.light_radius > 0:
        open_ = np.flatnonzero(~blocked)
        blocked[open_] = rim_hidden(
            caster, X[pv[open_]], P[pc[open_]], normals[pv[open_]], inp.light_radius,
            cfg.shadow_eps,
        )
    lit = np.ones(vertex.size, dtype=bool)
    lit[np.flatnonzero(keep)] = ~blocked[inverse]
    keep &= lit
    fixed = observed[keep] if inp.observed is not None else None
    obs = Observations.build(vertex[keep], frame[keep], fr, n, fixed)
    adj = adjacency(inp.faces, n)
    e = edges(adj)
    order = np.lexsort((frame[keep], view[keep], vertex[keep]))
    w = photometric_weights(
        e,
        obs.vertex,
        obs.illumination,
        observed[keep][order],
        s[keep][order],
        n,
        inp.rig.responses.shape[0],
        cfg.sigma_chroma,
        cfg.sigma_intensity,
    )
    highlight = None
    if cfg.highlights and obs.count:
        sel = np.flatnonzero(keep)[order]
        highlight = highlight_weights(
            np.repeat(np.arange(obs.pair_start.size), np.diff(np.r_[obs.pair_start, obs.count])),
            obs.vertex,
            obs.illumination,
            observed[sel],
            s[sel],
            inp.rig.responses.sum(axis=2),
            n,
            cfg.highlight_tolerance,
            half_angles(X[vertex[sel]], normals[vertex[sel]], P[view[sel]], centres[view[sel]]),
            np.radians(cfg.highlight_lobe_deg),
        )
        log.info(
            "highlights: %d of %d observations weigh below 1/2",
            int(np.sum(highlight < 0.5)),
            obs.count,
        )
    factor = highlight
    if weigh_taps:
        on_taps = taps[np.flatnonzero(keep)[order]]
        factor = on_taps if highlight is None else highlight * on_taps
    spectral = spectral_regulariser(cfg.spectral_prior, inp.basis)
    weights = Weights(cfg.gamma, e, w, edge_scale(X, adj), cfg.rendering_scale, factor, spectral)
    return Problem(
        inp.faces, n, inp.basis.B, inp.rig, fr, obs, weights, problem_mode(cfg.light_mode)
    )


def initial_reflectance(
    problem: Problem,
    theta: np.ndarray,
    basis: SpectralBasis,
    smoothness: float,
    upper: float = 1.0,
) -> np.ndarray:
    """α from the calibration module's 2-D estimate, per vertex, with the current shading:
    each (vertex, illumination)'s observations are pooled by least squares (each weighted by
    its rendering factor, so highlights count less) into one RGB and a shading weight;
    vertices never observed get the mean α. Reflectance within [0, ``upper``], regularised as
    the problem's spectral term is."""
    cost = JointCost(problem)
    X, A, light = problem.unpack(theta)
    normals, _ = vertex_normals(X, problem.faces)
    st = cost.render(X, A, light, normals, derivatives=False)
    o = problem.obs
    s = st.pair_s[cost.obs_pair]
    y_obs = s[:, None] * st.colours[o.illumination, o.vertex] - st.error
    n, k = problem.n_vertices, problem.rig.responses.shape[0]
    s2 = np.zeros((n, k))
    sy = np.zeros((n, k, 3))
    w2 = np.ones(o.count) if problem.weights.observation is None else problem.weights.observation**2
    np.add.at(s2, (o.vertex, o.illumination), w2 * s**2)
    np.add.at(sy, (o.vertex, o.illumination), (w2 * s)[:, None] * y_obs)
    seen = s2 > 0
    root = np.sqrt(s2)
    rgb = np.full((n, k, 3), np.nan)
    rgb[seen] = sy[seen] / root[seen][:, None]  # = root · (Σ s y / Σ s²)
    alpha = np.full((n, basis.n_components), np.nan)
    rows = np.flatnonzero(seen.any(axis=1))
    if rows.size:
        alpha[rows], _ = estimate_reflectance(
            rgb[rows],
            problem.rig.responses,
            basis,
            smoothness,
            shading=root[rows],
            bounds=(0.0, upper),
            regulariser=problem.weights.spectral or "smoothness",
        )
    good = np.all(np.isfinite(alpha), axis=1)
    fill = alpha[good].mean(axis=0) if good.any() else basis.project(np.full(basis.B.shape[0], 0.5))
    alpha[~good] = fill
    return alpha
