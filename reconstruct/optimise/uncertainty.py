"""Per-vertex uncertainty from the final Gauss–Newton linearisation.

Each vertex's block of JᵀJ + priors (the exact per-vertex blocks the solver's preconditioner
forms: rendering term, spectral smoothness, the vertex's share of the photometric smoothness and,
through the normals, of the geometric term) is taken over [t, α]: t the motion along the vertex
normal (the solver's ``position_motion: normal``; positions the solve kept fixed have no t) and
α the basis weights. Its inverse, scaled by the noise, is the vertex's covariance:

* noise: the rendering residuals give one image-noise variance per channel (χ² scale)
  ``s² = Σ_o (k w_f e_o)² / (3M − n_params)`` (k the rendering unit, w_f the frame's noise
  weight); the cost weighs vertex i's observations by ``1/|V(i)|``, so its block is scaled back
  with ``s² / |V(i)|`` — the priors are read at the same per-vertex scale as in the cost;
* ``Σ_α`` maps to a per-wavelength std ``sqrt(diag(B Σ_α Bᵀ))``; the position std is ``sqrt(Σ_tt)``.

Read as a prior, the smoothness regularisers claim far too much: 2 illuminations × 3 channels
see fewer directions than the N_b basis weights, the regularisers fill the rest, and their error
there (the metamer bias) dominates the actual error, while the plain covariance is smallest where
that bias is. So by default (``optimise.uncertainty_prior: training``) the reflectance covariance
is the data blocks (regularisers out) plus a Gaussian prior with the covariance of the basis
weights of the training reflectances: directions the camera sees get the noise, directions it
does not see keep the spread of real surfaces. The plain one stays as ``reflectance_std_gn``.

What this neglects (docs/usage-reconstruct.md): the coupling between vertices (neighbours held
at their estimates: a conditional, not marginal, covariance, so smoothing-dominated vertices look
surer than they are), the light's and the poses' uncertainty, calibration errors (camera
sensitivity, SPDs), the basis truncation and model errors beyond what the residuals show.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.basis import SpectralBasis
from calibration.defaults import training_reflectances
from reconstruct.optimise.cost import JointCost


@dataclass
class VertexUncertainty:
    reflectance_std: np.ndarray  # (N, N_λ); NaN for unobserved vertices
    position_std_m: np.ndarray  # (N,) along the normal; NaN where the position was not solved
    alpha_cov: np.ndarray  # (N, N_b, N_b); NaN for unobserved vertices
    noise_std: float  # per-channel image noise from the residuals, linear image units
    dof: int
    reflectance_std_gn: np.ndarray | None = None  # plain Gauss–Newton std (regularisers as prior)

    def summary(self) -> dict[str, float | int]:
        """Numbers for report.json."""
        mean_std = np.mean(self.reflectance_std, axis=1)  # NaN rows: unobserved
        pos = self.position_std_m[np.isfinite(self.position_std_m)]
        ok = np.isfinite(mean_std)
        return {
            "noise_std_linear": self.noise_std,
            "dof": self.dof,
            "reflectance_std_median": float(np.median(mean_std[ok])) if ok.any() else float("nan"),
            "reflectance_std_gn_median": (
                float(np.median(np.mean(self.reflectance_std_gn, axis=1)[ok]))
                if self.reflectance_std_gn is not None and ok.any()
                else float("nan")
            ),
            "reflectance_std_p90": float(np.percentile(mean_std[ok], 90))
            if ok.any()
            else float("nan"),
            "position_std_m_median": float(np.median(pos)) if pos.size else float("nan"),
            "position_std_m_p90": float(np.percentile(pos, 90)) if pos.size else float("nan"),
            "vertices_with_uncertainty": int(ok.sum()),
        }


def vertex_uncertainty(
    cost: JointCost,
    theta: np.ndarray,
    free_positions: np.ndarray,
    prior_cov: np.ndarray | None = None,
) -> VertexUncertainty:
    """Block-diagonal Gauss–Newton covariance at θ (module docstring); ``free_positions``
    (N,) bool: vertices whose position the last solve moved. With ``prior_cov`` (N_b, N_b) the
    reflectance std comes from the data blocks plus that prior on α instead of the smoothness
    regularisers (see the module docstring); ``reflectance_std_gn`` keeps the plain one."""
    p, o = cost.p, cost.p.obs
    n, nb = p.n_vertices, p.n_basis
    lin = cost.linearise(theta, positions=True)
    blk, _ = lin.diagonal_blocks()  # (N, 3 + N_b, 3 + N_b) over [x, α]
    normals = lin.geometry.normals
    lift = np.zeros((n, 1 + nb, 3 + nb))
    lift[:, 0, :3] = normals
    lift[:, 1:, 3:] = np.eye(nb)
    H = lift @ blk @ lift.transpose(0, 2, 1)
    fixed = ~np.asarray(free_positions, dtype=bool)
    H[fixed, 0, :] = 0.0
    H[fixed, :, 0] = 0.0
    H[fixed, 0, 0] = 1.0
    X, A, light = p.unpack(theta)
    geo = cost.geometry(X, derivatives=False)
    state = cost.render(X, A, light, geo.normals, derivatives=False)
    w = p.weights.rendering_scale * (
        np.ones(o.count) if p.frames.weight is None else np.asarray(p.frames.weight)[o.frame]
    )
    observed = o.per_vertex > 0
    n_params = int(observed.sum()) * nb + int((free_positions & observed).sum()) + p.n_light
    dof = max(3 * o.count - n_params, 1)
    s2 = float(np.sum((w[:, None] * state.error) ** 2)) / dof
    cov = np.full((n, 1 + nb, 1 + nb), np.nan)
    idx = np.flatnonzero(observed)
    scale = (s2 / o.per_vertex[idx])[:, None, None]
    cov[idx] = np.linalg.pinv(H[idx], hermitian=True) * scale
    B = cost.B
    gn_std = _spectral_std(B, cov[:, 1:, 1:])
    pos = np.sqrt(np.maximum(cov[:, 0, 0], 0.0))
    pos[fixed] = np.nan
    if prior_cov is not None:
        # data part only (regularisers out), in noise units, plus the reflectance prior
        data = H[idx].copy()
        data[:, 1:, 1:] -= cost.gamma[0] * cost.SS + cost.lap_diag[idx, None, None] * cost.BB
        precision = data / scale
        precision[:, 1:, 1:] += np.linalg.inv(prior_cov)
        cov[idx] = np.linalg.pinv(precision, hermitian=True)
    alpha_cov = cov[:, 1:, 1:]
    return VertexUncertainty(
        reflectance_std=_spectral_std(B, alpha_cov),
        position_std_m=pos,
        alpha_cov=alpha_cov,
        noise_std=float(np.sqrt(s2) / p.weights.rendering_scale),
        dof=dof,
        reflectance_std_gn=gn_std,
    )


def _spectral_std(B: np.ndarray, alpha_cov: np.ndarray) -> np.ndarray:
    """``sqrt(diag(B Σ_α Bᵀ))`` per vertex (N, N_λ)."""
    var = np.einsum("lb,nbc,lc->nl", B, alpha_cov, B)
    return np.sqrt(np.maximum(var, 0.0))


def reflectance_prior(basis: SpectralBasis) -> np.ndarray:
    """Covariance (N_b, N_b) of the basis weights of real surfaces (the training
    reflectances the basis is built from): how far a reflectance may lie off in directions
    the camera under the bulb's illuminations does not see."""
    return np.cov(basis.project(training_reflectances(basis.grid)), rowvar=False)
