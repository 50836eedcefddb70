"""Highlights: the observations that carry a glossy surface's neutral specular lobe, found by
their dichromatic signature and their geometry, and down-weighted in the rendering term.

The forward model is Lambertian. A glaze or varnish adds, near the mirror direction, light of
the lamp's own colour (the dichromatic model): under every illumination k of one (vertex, view)
pair the observation exceeds its diffuse value by ``h · Cᵀ L_k 1`` with one shared h ≥ 0. Left
in, such observations brighten the reflectance towards the lamp's colour and pull the light
towards the highlights. A vertex's diffuse value per illumination is the median over its views
of y / s: a highlight lies near the mirror direction, so few of the views that see a vertex see
it. A pair's difference from that value is split by least squares into a shading error (along
the pair's diffuse colours: a wrong normal or light scales all K alike) and a neutral part
(along the lamps' white responses); the pair is down-weighted smoothly where the neutral part
exceeds ``tolerance`` × the diffuse value plus three noise spreads (the robust spread of what
the split leaves, over all pairs), an allowance that grows away from the mirror direction.
Only surface colours tell the two parts apart: on a grey surface, whose diffuse colours are
the lamps' own, a shading error is neutral too, so a deficit counts as an excess does: the
model's errors, of either sign, are trimmed on both sides instead of darkening grey surfaces.
"""

from __future__ import annotations

import numpy as np

# noise spreads a Lambertian pair's neutral part by; beyond them it counts as a highlight
NOISE_SPREADS = 3.0


def group_median(group: np.ndarray, values: np.ndarray, n_groups: int) -> np.ndarray:
    """Median of the rows of ``values`` (M, c) in each group (per column), (n_groups, c);
    NaN for empty groups. One sort per column instead of a loop over groups."""
    counts = np.bincount(group, minlength=n_groups)
    start = np.r_[0, np.cumsum(counts)[:-1]]
    lo, hi = start + (counts - 1) // 2, start + counts // 2
    out = np.full((n_groups, values.shape[1]), np.nan)
    seen = counts > 0
    for c in range(values.shape[1]):
        v = values[np.lexsort((values[:, c], group)), c]
        out[seen, c] = 0.5 * (v[lo[seen]] + v[hi[seen]])
    return out


def neutral_excess(
    pair: np.ndarray,
    vertex: np.ndarray,
    illumination: np.ndarray,
    observed: np.ndarray,
    shading: np.ndarray,
    white: np.ndarray,
    n_vertices: int,
    tolerance: float,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Per (vertex, view) pair: the neutral part of its difference from the diffuse value
    (signed) and the diffuse value (image units, norms over the pair's K × 3 values, (P,)
    each), and the noise per value.

    ``pair`` (M,) numbers the observations' pairs 0..P−1; ``shading`` (M,) > 0; ``white``
    (K, 3) the lamps' white responses ``Cᵀ L_k 1``. The excess e is split as ``a d + h v``
    (d the diffuse values, v a unit white highlight) with the shading error a held to about
    ``tolerance`` (a ridge): on a coloured surface the split is free, on a grey one (d ∥ v) the
    whole excess along v counts as neutral."""
    k_count = white.shape[0]
    group = vertex.astype(np.int64) * k_count + illumination
    albedo = group_median(group, observed / shading[:, None], n_vertices * k_count)
    d = shading[:, None] * albedo[group]
    v = shading[:, None] * white[illumination]
    e = observed - d
    n_pairs = int(pair.max()) + 1

    def pair_sum(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.bincount(pair, weights=np.einsum("ij,ij->i", a, b), minlength=n_pairs)

    dd, vv, dv = pair_sum(d, d), pair_sum(v, v), pair_sum(d, v)
    ed, ev, ee = pair_sum(e, d), pair_sum(e, v), pair_sum(e, e)

    def split(ridge: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """(h, squared remainder) of the 2 × 2 normal equations with ``ridge`` on a."""
        det = np.maximum((dd + ridge) * vv - dv**2, 1e-300)
        a = (ed * vv - ev * dv) / det
        h = (ev * (dd + ridge) - ed * dv) / det
        rest = ee - 2 * a * ed - 2 * h * ev + a * a * dd + 2 * a * h * dv + h * h * vv
        return h, np.maximum(rest, 0.0)

    # the noise from the free split (a grey pair's remainder is the same under any split)
    _, rest = split(1e-9 * dd)
    dof = np.maximum(np.bincount(pair, minlength=n_pairs) * 3 - 2, 1)
    noise = float(np.sqrt(np.median(rest / dof)))
    h, _ = split(noise**2 / max(tolerance, 1e-12) ** 2)
    return h * np.sqrt(vv), np.sqrt(dd), noise


def highlight_weights(
    pair: np.ndarray,
    vertex: np.ndarray,
    illumination: np.ndarray,
    observed: np.ndarray,
    shading: np.ndarray,
    white: np.ndarray,
    n_vertices: int,
    tolerance: float,
    half_angle: np.ndarray,
    lobe_angle: float,
) -> np.ndarray:
    """Per observation (M,): a factor in (0, 1] on its rendering residual, 1/2 where its pair's
    neutral excess is ``tolerance`` × its diffuse value plus three noise spreads, falling as
    the fourth power beyond (flat below: noise keeps its weight). The allowance grows as
    ``1 + (θ_h / lobe_angle)⁴`` with the angle θ_h (radians, ``half_angle`` (M,)) between the
    normal and the half-vector of light and camera: a lobe lies near the mirror direction, far
    from it an excess is a shading error. A deficit counts as an excess does, so shading errors
    of a grey surface, which the split cannot take out, are trimmed on both sides alike."""
    if pair.size == 0:
        return np.ones(0)
    excess, diffuse, noise = neutral_excess(
        pair, vertex, illumination, observed, shading, white, n_vertices, tolerance
    )
    angle = np.bincount(pair, weights=half_angle) / np.bincount(pair)
    allowed = (tolerance * diffuse + NOISE_SPREADS * noise) * (1.0 + (angle / lobe_angle) ** 4)
    x = np.abs(excess) / np.maximum(allowed, 1e-300)
    return (1.0 / (1.0 + x**4))[pair]
