"""The chart check: a colour chart seen in a session's frames, its patches' reflectances
estimated through the session's own decode and calibration, compared with the reference.

Per view that shows the chart: the lit frames are decoded by the decode stage (its cache in
``recon/decoded/``, ambient frames subtracted), the chart is found on their sum, and each
patch's median linear RGB under every illumination gives ``y_pk = s_p · A_k ρ_p`` with the
session's response matrices ``A_k`` (calibration snapshot) and the 2-D estimator
(:mod:`calibration.estimation`). The shading ``s_p`` is unknown (distance, angle, exposure):
it is modelled as a plane over the chart, ``s = c0 + c1·u + c2·v`` in chart coordinates,
fitted robustly so that ``s_p · A_k ρ_ref,p`` (the RGB the calibration predicts for the
reference) matches the measured RGB over all patches, illuminations and channels. Three
numbers for the whole chart take the light's fall-off across it (a near point light changes
the irradiance by tens of percent over a chart), not the patches' own errors: a scalar field
cannot absorb an error that differs between channels, illuminations or neighbouring patches.
An overall gain error of the calibration is absorbed, so the check judges the patches' colour
and spectral shape and their lightness relative to each other. Views are combined by
the median spectrum per patch.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from calibration.basis import SpectralBasis, default_basis
from calibration.colour_difference import DEFAULT_ILLUMINANTS, Illuminant, delta_e00, illuminant
from calibration.estimation import (
    DEFAULT_SMOOTHNESS,
    estimate_reflectance,
    response_matrices,
)
from core.errors import RigError
from core.labels import AMBIENT
from core.lock import locked
from core.session import Session
from reconstruct.chart.detect import Layout, detect_chart, layout
from reconstruct.chart.patches import ChartPatches, read_values
from reconstruct.chart.reference import Reference
from reconstruct.frames import decode
from reconstruct.frames.ambient import exposure_ratio, subtract_ambient
from reconstruct.run.pipeline import session_spectra

log = logging.getLogger("reconstruct.chart")
CHECK_CHART = "rig check-chart"  # what a refused writer is told holds the session
SHADING_SCALE = 0.05  # relative RGB misfit beyond which a patch counts less (soft L1)


@dataclass(frozen=True)
class ViewCheck:
    """One view: the patches under each illumination, the fitted shading plane ``(c0, c1, c2)``
    and the estimated reflectance (N, N_λ)."""

    view: int
    patches: dict[str, ChartPatches]
    shading_plane: np.ndarray
    estimate: np.ndarray


@dataclass(frozen=True)
class ChartCheck:
    """The check's result: the estimate (median over ``views``) against ``reference``, ΔE00
    per patch for each illuminant (N,) and the spectral RMSE per patch (N,)."""

    reference: Reference
    estimate: np.ndarray
    views: list[ViewCheck]
    illuminations: list[str]
    delta_e: dict[str, np.ndarray]
    rmse: np.ndarray

    def summary(self) -> dict[str, float]:
        """Mean and max ΔE00 per illuminant and the mean spectral RMSE."""
        out: dict[str, float] = {}
        for name, de in self.delta_e.items():
            out[f"delta_e00_{name}_mean"] = float(np.nanmean(de))
            out[f"delta_e00_{name}_max"] = float(np.nanmax(de))
        out["rmse_mean"] = float(np.nanmean(self.rmse))
        return out


def chart_coordinates(chart: Layout) -> np.ndarray:
    """(N, 2) patch centres in chart coordinates, −1 … 1 across columns and rows."""
    rows, cols = np.divmod(np.arange(chart.size), chart.cols)
    u = (cols - (chart.cols - 1) / 2) / max((chart.cols - 1) / 2, 1)
    v = (rows - (chart.rows - 1) / 2) / max((chart.rows - 1) / 2, 1)
    return np.stack([u, v], axis=1)


def fit_shading(y: np.ndarray, predicted: np.ndarray, chart: Layout) -> np.ndarray:
    """The shading plane ``(c0, c1, c2)``: ``y_pkc ≈ (c0 + c1 u_p + c2 v_p) ŷ_pkc`` for the
    measured patch RGB ``y`` and the RGB ``ŷ = A_k ρ_p`` the calibration predicts for the
    reference (both (N, K, 3)), each patch weighted by 1/|ŷ_p| (dark patches count as much as
    light ones), with a soft-L1 loss (one patch far off moves it little)."""
    uv = chart_coordinates(chart)
    ok = np.all(np.isfinite(y), axis=(1, 2))
    if ok.sum() < 3:
        raise RigError(
            f"only {int(ok.sum())} chart patches could be read (saturated?)",
            "expose the chart so its white patch is below the sensor's clipping",
        )
    design = np.column_stack([np.ones(ok.sum()), uv[ok]])
    obs, pred = y[ok].reshape(ok.sum(), -1), predicted[ok].reshape(ok.sum(), -1)
    norm = np.linalg.norm(pred, axis=1, keepdims=True)
    start = np.array([float(np.median(obs.sum(axis=1) / pred.sum(axis=1))), 0.0, 0.0])
    fit = least_squares(
        lambda c: (((design @ c)[:, None] * pred - obs) / (norm * start[0])).ravel(),
        start,
        loss="soft_l1",
        f_scale=SHADING_SCALE,
    )
    return np.asarray(fit.x, dtype=float)


def estimate_view(
    patches: Mapping[str, ChartPatches],
    responses: np.ndarray,
    basis: SpectralBasis,
    reference: np.ndarray,
    chart: Layout,
    smoothness: float = DEFAULT_SMOOTHNESS,
) -> tuple[np.ndarray, np.ndarray]:
    """Reflectance per patch (N, N_λ) from the patches under each illumination (in the
    responses' order) and the shading plane it was divided by."""
    y = np.stack([p.rgb for p in patches.values()], axis=1)  # (N, K, 3)
    predicted = np.einsum("kcl,pl->pkc", responses, reference)
    plane = fit_shading(y, predicted, chart)
    shading = np.column_stack([np.ones(chart.size), chart_coordinates(chart)]) @ plane
    if not np.all(shading > 0):
        raise RigError(
            "the chart's fitted shading is not positive everywhere (chart mostly unreadable)",
            "frame the chart evenly lit, facing the camera",
        )
    _, refl = estimate_reflectance(y / shading[:, None, None], responses, basis, smoothness)
    return refl, plane


def _lit_image(
    decoded: Path, frames: Mapping[tuple[int, str], decode.DecodedFrame], key: tuple[int, str]
) -> tuple[np.ndarray, np.ndarray]:
    """A lit frame (image, saturation mask) less its view's ambient frame, if any."""
    frame = frames[key]
    img, sat = decode.load_frame(decoded, frame)
    amb = frames.get((key[0], AMBIENT))
    if amb is None:
        return img, sat
    amb_img, amb_sat = decode.load_frame(decoded, amb)
    ratio = exposure_ratio(frame.exposure_s, frame.iso, amb.exposure_s, amb.iso)
    out = subtract_ambient(img, ~sat, amb_img, ~amb_sat, ratio, f"view {key[0]} {key[1]}")
    return out.image, ~out.valid


def read_view(
    decoded: Path,
    frames: Mapping[tuple[int, str], decode.DecodedFrame],
    view: int,
    names: Sequence[str],
    chart: Layout,
) -> dict[str, ChartPatches] | None:
    """The chart's patches in ``view`` under each illumination (None: no chart found), found
    once on the sum of the lit frames."""
    lit = {n: _lit_image(decoded, frames, (view, n)) for n in names if (view, n) in frames}
    if len(lit) != len(names):
        log.warning("view %d lacks frames under %s: skipped", view, set(names) - set(lit))
        return None
    total = np.sum([img for img, _ in lit.values()], axis=0)
    geometry = detect_chart(total, chart)
    if geometry is None:
        log.info("view %d: no %s chart found", view, chart.name)
        return None
    patches = {n: read_values(img, geometry, sat) for n, (img, sat) in lit.items()}
    for name, p in patches.items():
        unread = np.flatnonzero(~np.all(np.isfinite(p.rgb), axis=1))
        if len(unread):
            log.warning(
                "view %d: patch(es) %s saturated under %s: left out there",
                view, ", ".join(str(k + 1) for k in unread), name,
            )  # fmt: skip
    return patches


def check_session(
    session: Session,
    reference: Reference,
    *,
    chart_layout: str = "classic24",
    views: Sequence[int] | None = None,
    decode_config: Mapping[str, Any] | None = None,
    illuminants: Sequence[Illuminant] | None = None,
    basis: SpectralBasis | None = None,
) -> ChartCheck:
    """The chart check of ``session`` (every view, or ``views``), holding its lock: the decode
    stage writes ``recon/decoded/``."""
    with locked(session.root, CHECK_CHART):
        return _check(session, reference, layout(chart_layout), views, decode_config,
                      illuminants, basis)  # fmt: skip


def _check(
    session: Session,
    reference: Reference,
    chart: Layout,
    views: Sequence[int] | None,
    decode_config: Mapping[str, Any] | None,
    illuminants: Sequence[Illuminant] | None,
    basis: SpectralBasis | None,
) -> ChartCheck:
    if len(reference.reflectance) != chart.size:
        raise RigError(
            f"reference {reference.source} has {len(reference.reflectance)} patches, the "
            f"{chart.name} chart {chart.size}",
            "give a reference file for this chart",
        )
    names = sorted(session.info.plan.illuminations or [])
    if not names:
        raise RigError(
            f"{session.root}/session.yaml names no illuminations (plan.illuminations)",
            "capture the session with a plan that names its illuminations",
        )
    camera, spds = session_spectra(session, names)
    responses = response_matrices(camera, [spds[n] for n in names])
    basis = basis or default_basis()
    decoded = decode.run(decode_config or {}, session, session.recon_dir / "decoded")
    index = decode.DecodeIndex.load(decoded)
    frames = {(f.view, f.illumination): f for f in index.frames}
    wanted = sorted({f.view for f in index.frames}) if views is None else list(views)
    missing = sorted(set(wanted) - {f.view for f in index.frames})
    if missing:
        raise RigError(
            f"{session.root} has no decoded frames of view(s) {missing}",
            f"choose among views {sorted({f.view for f in index.frames})}",
        )
    checks = []
    for view in wanted:
        patches = read_view(decoded, frames, view, names, chart)
        if patches is None:
            continue
        refl, plane = estimate_view(patches, responses, basis, reference.reflectance, chart)
        checks.append(ViewCheck(view, patches, plane, refl))
    if not checks:
        raise RigError(
            f"no {chart.name} colour chart found in view(s) {wanted} of {session.root}",
            "frame the whole chart, lit evenly, facing the camera, patches at least 20 px wide",
        )
    estimate = np.median(np.stack([c.estimate for c in checks]), axis=0)
    lights = list(illuminants or [illuminant(n) for n in DEFAULT_ILLUMINANTS])
    delta_e = {light.name: delta_e00(estimate, reference.reflectance, light) for light in lights}
    rmse = np.sqrt(np.mean((estimate - reference.reflectance) ** 2, axis=1))
    return ChartCheck(reference, estimate, checks, names, delta_e, rmse)
