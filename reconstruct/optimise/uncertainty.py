"""Per-vertex uncertainty from the final Gauss–Newton linearisation.

Each vertex's block of JᵀJ + priors (the exact per-vertex blocks the solver's preconditioner
forms: rendering term, spectral smoothness, the vertex's share of the photometric smoothness and,
through the normals, of the geometric term) is taken over [t, α]: t the motion along the vertex
normal (the solver's joint stages move vertices along it; positions kept fixed have no t) and
α the basis weights.

* noise: the rendering residuals give one image-noise variance per channel (χ² scale)
  ``s² = Σ_o (k w_f e_o)² / (3M − n_params)`` (k the rendering unit, w_f the frame's noise
  weight); the cost weighs vertex i's observations by ``1/|V(i)|``, so its block is read in
  noise units as ``block / (s² / |V(i)|)`` — the priors at the same per-vertex scale as in the
  cost;
* α maps to a per-wavelength std ``sqrt(diag(B C Bᵀ))``; the position std is ``sqrt(C_tt)``.

Read as a prior, the smoothness regularisers claim far too much: 2 illuminations × 3 channels
see fewer directions than the N_b basis weights, the regularisers fill the rest, and their error
there (the metamer bias) dominates the actual error, while the plain covariance is smallest where
that bias is. So the std is about the *reported* estimate θ̂ under a Gaussian posterior made
of the data blocks (regularisers out) and the training reflectances' basis weights
N(μ, Σ) (a :class:`ReflectancePrior`) as the prior on α:

* posterior covariance ``Σ_post = (D + Σ⁻¹)⁻¹`` (D the data precision over [t, α]; t keeps the
  geometric term as its prior);
* the estimate is not the posterior mean: the regularisers pulled it. Linearised at θ̂,
  ``θ̂ − m_post = Σ_post (g + Σ⁻¹(α̂ − μ))`` with g the data gradient (t: the whole gradient,
  its prior included), and the expected squared error of θ̂ is ``Σ_post + d dᵀ``. d is
  vertex-specific: large where the regularisers decided against what data and real surfaces say;
* the basis cannot represent a real reflectance exactly: the training set's mean squared
  residual outside the basis span is added per wavelength;
* the band a user sees is the shortest 95 % interval of that error's normal truncated to the
  physical range (:func:`calibration.bounds.bounded_band`): near 0 or 1 a ±2σ band would claim
  reflectances that cannot exist.

Neighbour coupling: with the regularisers out of the prior, vertices couple only through the
normals, the geometric term and the light, weakly enough that the per-vertex blocks stand in for
the whole linearised system. What this neglects (docs/usage-reconstruct.md): a solve that settles
where its linearisation cannot tell it is wrong (shape and light off far beyond their local std,
which scales the reflectance of whole regions), calibration errors (camera sensitivity, SPDs) and
model errors beyond what the residuals show.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from calibration.basis import SpectralBasis
from calibration.bounds import bounded_band
from calibration.defaults import training_reflectances
from calibration.prior import WeightStatistics as ReflectancePrior
from calibration.prior import weight_statistics
from reconstruct.optimise.cost import JointCost


@dataclass
class VertexUncertainty:
    reflectance_std: np.ndarray  # (N, N_λ); NaN for unobserved vertices
    # the 95 % band within the physical range (N, N_λ) each; NaN for unobserved vertices
    reflectance_low: np.ndarray
    reflectance_high: np.ndarray
    position_std_m: np.ndarray  # (N,) along the normal; NaN where the position was not solved
    alpha_cov: np.ndarray  # (N, N_b, N_b) expected squared error of α̂; NaN for unobserved
    noise_std: float  # per-channel image noise from the residuals, linear image units
    dof: int
    reflectance_std_gn: np.ndarray | None = None  # plain Gauss–Newton std (regularisers as prior)

    def colour_from(self, source: np.ndarray) -> VertexUncertainty:
        """The uncertainty where each vertex's reflectance is that of vertex ``source`` (N,):
        the colour rows move with it, the position's stays."""
        gn = self.reflectance_std_gn
        return replace(
            self,
            reflectance_std=self.reflectance_std[source],
            reflectance_low=self.reflectance_low[source],
            reflectance_high=self.reflectance_high[source],
            alpha_cov=self.alpha_cov[source],
            reflectance_std_gn=None if gn is None else gn[source],
        )

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
    prior: ReflectancePrior,
    upper: float = 1.0,
) -> VertexUncertainty:
    """Per-vertex std at θ (module docstring); ``free_positions`` (N,) bool: vertices whose
    position the last solve moved; ``upper``: the reflectance's upper bound (its band's). The
    std is the expected error of the estimate under the data and ``prior`` (regularisers out);
    ``reflectance_std_gn`` is the plain Gauss–Newton std with the regularisers as the prior."""
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
    gx, ga, _ = p.unpack(lin.gradient())
    reg_grad = cost.gamma[0] * A @ cost.SS + (cost.laplacian @ A) @ cost.BB
    grad = np.zeros((n, 1 + nb))
    grad[:, 0] = np.where(fixed, 0.0, np.einsum("ij,ij->i", gx, normals))
    grad[:, 1:] = ga - reg_grad
    data = H[idx].copy()
    data[:, 1:, 1:] -= cost.gamma[0] * cost.SS + cost.lap_diag[idx, None, None] * cost.BB
    cov[idx] = expected_error(data / scale, grad[idx] / scale[:, :, 0], A[idx], prior)
    var = _spectral_var(B, cov[:, 1:, 1:]) + prior.truncation_var
    pos = np.sqrt(np.maximum(cov[:, 0, 0], 0.0))
    pos[fixed] = np.nan
    std = np.sqrt(np.maximum(var, 0.0))
    low, high = bounded_band(A @ B.T, std, 0.0, upper)
    return VertexUncertainty(
        reflectance_std=std,
        reflectance_low=low,
        reflectance_high=high,
        position_std_m=pos,
        alpha_cov=cov[:, 1:, 1:],
        noise_std=float(np.sqrt(s2) / p.weights.rendering_scale),
        dof=dof,
        reflectance_std_gn=gn_std,
    )


def expected_error(
    data: np.ndarray, grad: np.ndarray, alpha: np.ndarray, prior: ReflectancePrior
) -> np.ndarray:
    """``E[(θ̂ − θ)(θ̂ − θ)ᵀ] = Σ_post + d dᵀ`` per vertex (K, 1 + N_b, 1 + N_b) over [t, α],
    from the data precision ``data`` (K, 1 + N_b, 1 + N_b) and data gradient ``grad``
    (K, 1 + N_b) at the estimate (noise units; ½∇ of χ²) and the prior N(μ, Σ) on α:
    ``Σ_post = (D + Σ⁻¹)⁻¹``, ``d = θ̂ − m_post = Σ_post (g + Σ⁻¹(α̂ − μ))``."""
    inv_prior = np.linalg.inv(prior.cov)
    precision = data.copy()
    precision[:, 1:, 1:] += inv_prior
    post = np.linalg.pinv(precision, hermitian=True)
    g = grad.copy()
    g[:, 1:] += (alpha - prior.mean) @ inv_prior
    d = np.einsum("kij,kj->ki", post, g)
    return post + d[:, :, None] * d[:, None, :]


def _spectral_var(B: np.ndarray, alpha_cov: np.ndarray) -> np.ndarray:
    """``diag(B C Bᵀ)`` per vertex (N, N_λ)."""
    return np.einsum("lb,nbc,lc->nl", B, alpha_cov, B, optimize=True)  # 9× faster at 100k


def _spectral_std(B: np.ndarray, alpha_cov: np.ndarray) -> np.ndarray:
    """``sqrt(diag(B C Bᵀ))`` per vertex (N, N_λ)."""
    return np.sqrt(np.maximum(_spectral_var(B, alpha_cov), 0.0))


def reflectance_prior(basis: SpectralBasis) -> ReflectancePrior:
    """Mean and covariance of the basis weights of real surfaces (the training reflectances
    the basis is built from) — how far a reflectance may lie in directions the camera under the
    bulb's illuminations does not see — and their mean squared residual outside the basis span
    (what no weights can represent)."""
    stats = weight_statistics(basis, training_reflectances(basis.grid))
    return ReflectancePrior(stats.mean, stats.cov, stats.truncation_var)
