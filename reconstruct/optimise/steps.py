"""The paper's optimisation steps (Sec. 3.4): light offset from 0, a light-only stage with the
vertices fixed, then joint stages; between stages the observation set is rebuilt from the current
mesh — shadow masks by ray casting to the current lights, projections inside the image and off
saturated pixels, photometric weights and geometric scales — until the parameters settle.

Every stage keeps each vertex's reflectance within [0, ``OptimiseInput.reflectance_upper``]
(the solver's ``reflectance_bounds``: projected Levenberg–Marquardt).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from calibration.bounds import project
from calibration.prior import spectral_regulariser
from calibration.unseen import UNSEEN_SHARE, complete_unseen, seen_strengths
from core.errors import RigError
from reconstruct.optimise.checkpoint import Checkpoint, OptimiseState
from reconstruct.optimise.cost import JointCost
from reconstruct.optimise.gloss import GlossFit, colour_without_gloss, without_gloss
from reconstruct.optimise.mesh import (
    adjacency,
    carried_along,
    relax_tangentially,
    vertex_normals,
)
from reconstruct.optimise.pooling import pooled_sources
from reconstruct.optimise.problem import Problem
from reconstruct.optimise.problem_setup import (
    build_problem,
    initial_reflectance,
    light_positions,
)
from reconstruct.optimise.sampling import blur_frames
from reconstruct.optimise.settings import OptimiseInput, OptimiseSettings
from reconstruct.optimise.solver import IterationRecord, SolverSettings, levenberg_marquardt
from reconstruct.optimise.uncertainty import (
    VertexUncertainty,
    reflectance_prior,
    vertex_uncertainty,
)
from reconstruct.optimise.weights import edge_scale

log = logging.getLogger(__name__)
@dataclass
class OptimiseResult:
    vertices: np.ndarray
    faces: np.ndarray
    alpha: np.ndarray
    reflectance: np.ndarray
    light: np.ndarray  # offset (1, 3) or free positions (N_views, 3)
    light_positions: np.ndarray  # (N_views, 3)
    observed: np.ndarray  # vertices with at least one observation in the last solve (N,) bool
    n_observations: int
    history: list[dict[str, Any]]
    stage_seconds: dict[str, float]
    initial_alpha: np.ndarray
    uncertainty: VertexUncertainty | None = None  # at the final θ (optimise/uncertainty.py)
    # per vertex, the vertex whose reflectance it carries: itself, or a settled neighbour
    # where its own shape was left folded (optimise/pooling.py)
    colour_source: np.ndarray | None = None

    @property
    def colour_from_neighbours(self) -> int | None:
        """How many vertices carry a neighbour's colour (None: not recorded)."""
        if self.colour_source is None:
            return None
        return int(np.count_nonzero(self.colour_source != np.arange(len(self.colour_source))))


Progress = Callable[[str, IterationRecord], None]


def limit_motion(
    X: np.ndarray,
    X_prev: np.ndarray,
    X0: np.ndarray,
    step_radius: np.ndarray,
    total_radius: np.ndarray,
) -> np.ndarray:
    """Project each vertex back into its trust regions: a ball of ``step_radius`` around its
    stage start, then one of ``total_radius`` around the initial mesh (metres, per vertex)."""

    def clamp(x: np.ndarray, centre: np.ndarray, radius: np.ndarray) -> np.ndarray:
        d = x - centre
        norm = np.linalg.norm(d, axis=1)
        factor = np.minimum(1.0, radius / np.maximum(norm, 1e-300))
        return centre + d * factor[:, None]

    return clamp(clamp(X, X_prev, step_radius), X0, total_radius)


def coarse_blurs(cfg: OptimiseSettings, images: bool) -> list[float]:
    """Blur σ (px) of each coarse level, coarsest first; none without images to blur."""
    if cfg.coarse_blur_px <= 0 or not images or not cfg.optimise_positions:
        return []
    return [cfg.coarse_blur_px / 2**k for k in range(cfg.coarse_levels)]


def view_pixel_sizes(X: np.ndarray, inp: OptimiseInput) -> np.ndarray:
    """Metres per pixel of each view at the object (median depth of its visible vertices /
    focal length); views that see nothing take the median of the others."""
    out = np.full(inp.rig.n_views, np.nan)
    for c, (pose, intr) in enumerate(zip(inp.rig.poses, inp.rig.intrinsics, strict=True)):
        seen = inp.visibility[:, c]
        if seen.any():
            depth = pose.to_camera(X[seen])[:, 2]
            out[c] = float(np.median(depth)) / float(intr.K[0, 0])
    return np.where(np.isfinite(out), out, np.nanmedian(out))


def optimise(
    inp: OptimiseInput,
    settings: OptimiseSettings | None = None,
    progress: Progress | None = None,
    checkpoint: Checkpoint | None = None,
) -> OptimiseResult:
    """Run the paper's optimisation steps and return the refined mesh, reflectance and light.
    With a ``checkpoint`` the state is saved after each stage, and a saved state for the same
    inputs is resumed after its last completed stage."""
    cfg = settings or OptimiseSettings()
    X = np.array(inp.vertices, dtype=float)
    n_views = inp.rig.n_views
    if inp.initial_light is not None:
        light = np.asarray(inp.initial_light, dtype=float).reshape(-1, 3)
    elif cfg.light_mode == "offset":
        light = np.zeros((1, 3))  # paper: v starts at the camera centre
    elif cfg.light_mode == "fixed":
        raise RigError(
            "light mode `fixed` needs known light positions (one per view)",
            "use it on projector sessions (recon/procam/ lights) or set optimise.light_mode",
        )
    else:
        light = np.stack([pose.center for pose in inp.rig.poses])
    if light.shape != ((1, 3) if cfg.light_mode == "offset" else (n_views, 3)):
        raise RigError(
            f"initial light has shape {light.shape} for light mode {cfg.light_mode}",
            "give one offset (3,) or one position per view (N_views, 3)",
        )
    history: list[dict[str, Any]] = []
    seconds: dict[str, float] = {}
    nb = inp.basis.n_components
    B, upper = inp.basis.B, inp.reflectance_upper

    def run(
        stage: str,
        outer: int,
        problem: Problem,
        theta: np.ndarray,
        mask: np.ndarray,
        iterations: int,
        directions: np.ndarray | None = None,
        constrain: Callable[[np.ndarray], np.ndarray] | None = None,
        gloss: GlossFit | None = None,
    ) -> np.ndarray:
        t0 = time.perf_counter()
        cost = JointCost(problem, cfg.robust, cfg.robust_scale)
        # With the stage's `positions` the solver's first linearisation reuses this render.
        start = cost.terms(theta, positions=bool(mask[problem.slices()[0]].any()))
        history.append(
            {
                "stage": stage,
                "outer": outer,
                "iteration": 0,
                "terms": start,
                "step": 0.0,
                "lambda": None,
                "cg_iterations": 0,
                "accepted": True,
                "seconds": 0.0,
                "observations": problem.obs.count,
                **({} if gloss is None else {"gloss": gloss.summary()}),
            }
        )

        def record(rec: IterationRecord) -> None:
            history.append(
                {
                    "stage": stage,
                    "outer": outer,
                    "iteration": rec.iteration,
                    "terms": rec.terms,
                    "step": rec.step_norm,
                    "lambda": rec.lam,
                    "cg_iterations": rec.cg_iterations,
                    "accepted": rec.accepted,
                    "seconds": rec.seconds,
                    "observations": problem.obs.count,
                }
            )
            if progress:
                progress(f"{stage} {outer}", rec)

        solver = SolverSettings(**{**cfg.solver.__dict__, "max_iterations": iterations})
        result = levenberg_marquardt(
            cost, theta, mask, solver, record, directions, constrain, (0.0, upper)
        )
        seconds[stage] = seconds.get(stage, 0.0) + time.perf_counter() - t0
        log.info(
            "%s %d: %s after %d iterations", stage, outer, result.stop_reason, len(result.history)
        )
        return result.theta

    blurs = coarse_blurs(cfg, inp.observed is None)
    last_outer = len(blurs) + cfg.outer_iterations if cfg.optimise_positions else 0
    # with the gloss lobe, or edge taps to weigh in images: a colour stage last
    colour_stage = cfg.gloss == "fit" or (cfg.tap_gradient_scale > 0 and inp.observed is None)
    last_stage = last_outer + colour_stage
    free_light = cfg.light_mode != "fixed"
    X0 = X.copy()
    scale0 = edge_scale(X0, adjacency(inp.faces, len(X0)))
    # Coarse levels: one σ in metres at the object for all views, each view's σ in its pixels.
    pixel = view_pixel_sizes(X0, inp) if blurs else np.ones(n_views)
    pixel_ref = float(np.median(pixel))
    total_radius = cfg.max_total_edges * scale0 + pixel_ref * sum(blurs)
    levels: dict[int, OptimiseInput] = {}

    def level(outer: int) -> OptimiseInput:
        """The input of joint stage ``outer`` (light stage: 0): blurred frames while coarse."""
        k = max(outer, 1) - 1
        if k >= len(blurs):
            levels.clear()  # the full-resolution stages need no blurred copy
            return inp
        if k not in levels:
            levels.clear()  # one blurred copy of the images at a time
            sigma = blurs[k] * pixel_ref / pixel
            levels[k] = replace(inp, frames=blur_frames(inp.frames, sigma))
        return levels[k]

    def save(stage: int, done: bool, theta: np.ndarray, problem: Problem) -> None:
        if checkpoint is None:
            return
        X, A, light = problem.unpack(theta)
        checkpoint.save(
            OptimiseState(
                stage,
                done or stage >= last_stage,
                X,
                A,
                light,
                A0,
                problem.obs.per_vertex > 0,
                problem.obs.count,
                history,
                seconds,
            )
        )

    state = checkpoint.load() if checkpoint is not None else None
    if state is not None:
        log.info("resuming the optimisation after stage %d (%s)", state.stage, checkpoint)
        history[:], A0 = state.history, state.initial_alpha
        seconds.update(state.seconds)
        finished = state.done and colour_stage  # ended on the colour stage's weights
        problem = build_problem(inp, state.vertices, state.light, cfg, colour_stage=finished)
        theta = problem.pack(state.vertices, project(state.alpha, B, 0.0, upper), state.light)
        # a finished solve goes straight to its uncertainty and the result
        first_outer = last_outer + 1 if state.done else state.stage + 1
    else:
        t0 = time.perf_counter()
        A0 = np.zeros((len(X), nb)) if inp.initial_alpha is None else np.asarray(inp.initial_alpha)
        problem = build_problem(level(0), X, light, cfg)
        if problem.obs.count == 0:
            raise RigError(
                "no vertex is observed in any frame (all outside the images, saturated or "
                "shadowed)",
                "check the poses and the initial mesh, and the exposure of the captures",
            )
        if inp.initial_alpha is None:
            theta = problem.pack(X, A0, light)
            A0 = initial_reflectance(problem, theta, inp.basis, cfg.init_smoothness, upper)
        else:
            A0 = project(A0, B, 0.0, upper)
        theta = problem.pack(X, A0, light)
        seconds["setup"] = time.perf_counter() - t0
        theta = run(
            "light", 0, problem, theta, problem.mask(False, True, free_light), cfg.light_iterations
        )
        if cfg.gloss == "fit":  # again, from a start with the found light's highlights taken off
            problem, fit = without_gloss(problem, theta)
            A0 = initial_reflectance(problem, theta, inp.basis, cfg.init_smoothness, upper)
            theta = problem.pack(X, A0, problem.unpack(theta)[2])
            theta = run(
                "light", 0, problem, theta, problem.mask(False, True, free_light),
                cfg.light_iterations, gloss=fit,
            )
        save(0, False, theta, problem)
        first_outer = 1
    for outer in range(first_outer, last_outer + 1):
        t0 = time.perf_counter()
        X_prev, _, light_prev = problem.unpack(theta)
        X_prev, light_prev = X_prev.copy(), light_prev.copy()
        coarse = outer <= len(blurs)
        problem = build_problem(level(outer), X_prev, light_prev, cfg)
        gloss: GlossFit | None = None
        if cfg.gloss == "fit":
            problem, gloss = without_gloss(problem, theta)
        seconds["shadows"] = seconds.get("shadows", 0.0) + time.perf_counter() - t0
        # Vertices no view observes have no data term: only the geometric term (blind to
        # tangential motion) would move them, so the solve holds them; so it does vertices
        # seen from too few views (no parallax, one bad view decides). After the stage they
        # are carried along with the surface around them.
        o = problem.obs
        views = np.bincount(o.vertex[o.pair_start], minlength=problem.n_vertices)
        mask = problem.mask(True, True, free_light)
        mask[problem.slices()[0]] = np.repeat(views >= max(cfg.min_views, 1), 3)
        directions, _ = vertex_normals(X_prev, problem.faces)
        stage = "coarse" if coarse else "joint"
        step_radius = cfg.max_step_edges * problem.weights.scale
        if coarse:  # the blurred cue reaches σ: let the vertices follow it
            step_radius = np.maximum(step_radius, blurs[outer - 1] * pixel_ref)

        def within_reach(
            theta: np.ndarray,
            problem: Problem = problem,
            X_prev: np.ndarray = X_prev,
            step_radius: np.ndarray = step_radius,
        ) -> np.ndarray:
            """Trial steps stay in the trust regions, so LM never takes a step the stage end
            would undo (a weakly held vertex flung far and clamped back breaks its ring)."""
            X, A, light = problem.unpack(theta)
            return problem.pack(limit_motion(X, X_prev, X0, step_radius, total_radius), A, light)

        theta = run(
            stage, outer, problem, theta, mask, cfg.joint_iterations, directions, within_reach,
            gloss,
        )
        X_new, A_new, light_new = problem.unpack(theta)
        moved = float(np.max(np.linalg.norm(X_new - X_prev, axis=1)))
        # the vertices held for want of views carried along with the surface around them,
        # then what the stage moved along the normals evened out along the surface (within
        # the same bounds as the stage's own steps)
        movable = views >= max(cfg.min_views, 1)
        X_new = X_prev + carried_along(X_new - X_prev, problem.faces, movable)
        X_even = relax_tangentially(X_new, problem.faces, movable)
        theta = within_reach(problem.pack(X_even, A_new, light_new))
        light_moved = float(np.max(np.linalg.norm(light_new - light_prev, axis=1)))
        tol = cfg.settle_position * float(np.mean(problem.weights.scale))
        log.info("outer %d: vertices moved ≤ %.3g m, light ≤ %.3g m", outer, moved, light_moved)
        settled = not coarse and moved <= tol and light_moved <= cfg.settle_light_m
        if settled and last_stage > last_outer:  # the joint stages left are skipped on a resume too
            save(last_outer, False, theta, problem)
        else:
            save(outer, settled, theta, problem)
        if settled:
            break
    if last_stage > last_outer and not (state is not None and state.done):
        # the reflectance once more from the observations as they are (highlights down-weighted
        # when that is on), edge taps weighing less, at full resolution and the final shape and
        # light, as a resumed solve rebuilds them
        t0 = time.perf_counter()
        X, _, light = problem.unpack(theta)
        problem = build_problem(inp, X, light, cfg, colour_stage=True)
        seconds["shadows"] = seconds.get("shadows", 0.0) + time.perf_counter() - t0
        theta = run(
            "colour", last_stage, problem, theta, problem.mask(False, True, False),
            cfg.joint_iterations,
        )
        if cfg.gloss == "fit":  # and again with the lobe off, where it is the gloss
            glossless, gloss = colour_without_gloss(problem, theta)
            if gloss is not None:
                theta = run(
                    "colour", last_stage + 1, glossless, theta,
                    problem.mask(False, True, False), cfg.joint_iterations, gloss=gloss,
                )
        save(last_stage, True, theta, problem)
    t0 = time.perf_counter()
    if problem.frames is not inp.frames:  # ended on a coarse level: judge it at full resolution
        X, _, light = problem.unpack(theta)
        problem = build_problem(inp, X, light, cfg)
    X, A, light = problem.unpack(theta)
    spectral = problem.weights.spectral or spectral_regulariser("smoothness", inp.basis)
    share = cfg.weakly_seen_share
    A = complete_unseen(A, B, inp.rig.responses, spectral.matrix, share, 0.0, upper)
    strength = seen_strengths(B, inp.rig.responses)
    weak, unseen = int(np.sum(strength < share)), int(np.sum(strength < UNSEEN_SHARE))
    log.info(
        "%d of %d spectral directions set by the regulariser: %d unseen, %d seen below %.2g of "
        "the strongest", weak, B.shape[1], unseen, weak - unseen, share
    )
    theta = problem.pack(X, A, light)
    solved = cfg.optimise_positions and last_outer > 0
    o = problem.obs
    views = np.bincount(o.vertex[o.pair_start], minlength=problem.n_vertices)
    uncertainty = vertex_uncertainty(
        JointCost(problem, cfg.robust, cfg.robust_scale),
        theta,
        (views >= max(cfg.min_views, 1)) & solved,
        reflectance_prior(inp.basis),
        upper,
    )
    seconds["uncertainty"] = time.perf_counter() - t0
    X, A, light = problem.unpack(theta)
    observed, count = problem.obs.per_vertex > 0, problem.obs.count
    if state is not None and state.done:  # as the finished solve saw them, not re-derived
        observed, count = state.observed, state.n_observations
    # the agreement is in reflectance units, which a scale known only up to a factor lacks
    pooling = cfg.pooling if np.isfinite(upper) else replace(cfg.pooling, max_fold_deg=0.0)
    source = pooled_sources(X, problem.faces, inp.basis.reconstruct(A), observed, pooling)
    A, uncertainty = A[source], uncertainty.colour_from(source)
    final = OptimiseState(0, True, X, A, light, A0, observed, count, history, seconds)
    result = _result(inp, cfg, X, A, light, final, A0, history, uncertainty, source)
    log.info(
        "%d folded vertices take the colour of settled neighbours", result.colour_from_neighbours
    )
    return result


def _result(
    inp: OptimiseInput,
    cfg: OptimiseSettings,
    X: np.ndarray,
    A: np.ndarray,
    light: np.ndarray,
    state: OptimiseState,
    A0: np.ndarray,
    history: list[dict[str, Any]],
    uncertainty: VertexUncertainty,
    colour_source: np.ndarray,
) -> OptimiseResult:
    return OptimiseResult(
        vertices=X.copy(),
        faces=np.asarray(inp.faces),
        alpha=A.copy(),
        # the solver keeps B α within the bounds; this trims its float round-off (< 1e-10)
        reflectance=np.clip(inp.basis.reconstruct(A), 0.0, inp.reflectance_upper),
        light=light.copy(),
        light_positions=light_positions(inp.rig, cfg.light_mode, light),
        observed=state.observed,
        n_observations=state.n_observations,
        history=history,
        stage_seconds=state.seconds,
        initial_alpha=A0,
        uncertainty=uncertainty,
        colour_source=colour_source,
    )
