"""A camera's spectral sensitivity estimated from photos of a ColorChecker under measured lamps.

The model of one photo p of the chart's 24 patches is ``y_pic = k_p · Σ_λ S_c(λ) L_p(λ) R_i(λ)``:
the lamp's SPD L_p and the patches' reflectances R_i are known, the sensitivity S and one
exposure factor k_p per photo (exposure time, aperture, lamp distance and brightness) are not.
Twenty-four patches under one lamp cannot pin down 31 samples per channel, so the fit is a
maximum a-posteriori estimate under a Gaussian prior learnt from measured cameras (Jiang et al.,
WACV 2013: their PCA of 28 cameras, two components per channel, generalised):

* per channel, the training curves' mean plus their first ``n_components`` principal
  components with the training set's variance along each (probabilistic PCA); along every other
  direction the variance a camera left out of the set shows (leave-one-out), so a camera unlike
  the training set can still be fitted where the photos say so;
* the curves are non-negative (bounded least squares);
* each patch value has a relative plus a floor error (:class:`PatchNoise`);
* the light may fall off across the chart: per photo a plane over the chart's patch grid
  (:func:`chart_coordinates`) multiplies the exposure, as in the chart check of
  ``rig check-chart``, so a lamp at arm's length does not bend the curves;
* the sensitivity and the exposures (in log, so they stay positive) are solved together by
  bounded Gauss-Newton (scipy's trust-region reflective least squares), from the prior's mean.

The prior's curves are normalised as the store keeps them (maximum over channels and
wavelengths = 1, calibration.store), which fixes the scale the exposures would otherwise share
with S; the returned sensitivity is normalised the same way.

The prior and its training sets (a camspec file or folder, or the cameras in a store) are
:mod:`calibration.camera_prior`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from calibration.camera_prior import (
    SensitivityPrior,
)
from core.errors import RigError

CHART_PATCHES = 24
CHANNELS = ("R", "G", "B")


# -- the fit ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PatchNoise:
    """The error assumed for a patch value: ``relative`` of the value plus ``floor`` of the
    photo's brightest patch value, as standard deviations. The relative term stands for what a
    photo of a real chart adds beyond sensor noise: the printed chart against its reference
    reflectances, the lamp against its measured SPD, uneven light."""

    relative: float = 0.01
    floor: float = 0.002

    def sigma(self, normalised: np.ndarray) -> np.ndarray:
        return np.sqrt((self.relative * normalised) ** 2 + self.floor**2)


@dataclass
class CameraFit:
    """An estimated sensitivity and how well it explains the photos.

    ``sensitivity`` (N_λ, 3), maximum 1; ``posterior_std`` its standard deviation (same units,
    from the fit's curvature, bounds ignored); ``exposure`` (P,) the factor per photo;
    ``predicted`` and ``observed`` (P, 24, 3) patch values; ``prior_distance`` (3,) the
    estimate's Mahalanobis distance from the prior's mean, per channel, over N_λ dimensions
    (training cameras: :attr:`training_distances`)."""

    sensitivity: np.ndarray
    posterior_std: np.ndarray
    exposure: np.ndarray
    shading: np.ndarray
    predicted: np.ndarray
    observed: np.ndarray
    prior_distance: np.ndarray
    training_distances: np.ndarray
    evaluations: int
    prior: SensitivityPrior = field(repr=False)

    @property
    def relative_residual(self) -> np.ndarray:
        """(predicted − observed) / the photo's brightest patch value, (P, 24, 3)."""
        scale = self.observed.max(axis=(1, 2), keepdims=True)
        return np.asarray((self.predicted - self.observed) / scale)

    def patch_error_percent(self) -> np.ndarray:
        """RMS over channels of :attr:`relative_residual`, in % (P, 24)."""
        return np.asarray(100 * np.sqrt(np.mean(self.relative_residual**2, axis=2)))

    def patch_angle_deg(self) -> np.ndarray:
        """Angle between predicted and observed RGB per patch, degrees (P, 24)."""
        return rgb_angle_deg(self.predicted, self.observed)

    def nearest_training_camera(self) -> tuple[str, float]:
        """The training camera closest to the estimate and the RMSE between them."""
        diff = self.prior.training.sensitivities - self.sensitivity[None]
        rmse = np.sqrt(np.mean(diff**2, axis=(1, 2)))
        best = int(np.argmin(rmse))
        return self.prior.training.names[best], float(rmse[best])

    def summary(self) -> dict[str, float | int | str]:
        """The numbers a store entry's provenance keeps."""
        err = self.patch_error_percent()
        near, near_rmse = self.nearest_training_camera()
        return {
            "photos": int(self.observed.shape[0]),
            "patch_error_rms_percent": round(float(np.sqrt(np.mean(err**2))), 3),
            "patch_error_max_percent": round(float(err.max()), 3),
            "patch_angle_mean_deg": round(float(self.patch_angle_deg().mean()), 3),
            "light_unevenness_percent": round(float(np.ptp(self.shading, axis=1).max() * 100), 1),
            "prior_distance_rgb": ", ".join(f"{d:.2f}" for d in self.prior_distance),
            "prior_distance_training_median": round(float(np.median(self.training_distances)), 2),
            "prior_components": self.prior.n_components,
            "prior_cameras": len(self.prior.training.names),
            "nearest_training_camera": f"{near} (RMSE {near_rmse:.3f})",
        }


def rgb_angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in degrees between RGB (or any) vectors along the last axis."""
    cos = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.asarray(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def validate_patches(patch_rgb: np.ndarray, white_level: float | None = None) -> np.ndarray:
    """Patch values as (P, 24, 3) floats, or one :class:`RigError` line naming the photo, patch
    and channel that is missing, negative or (with ``white_level``) saturated."""
    y = np.asarray(patch_rgb, dtype=float)
    if y.ndim == 2:
        y = y[None]
    if y.ndim != 3 or y.shape[1:] != (CHART_PATCHES, 3):
        raise RigError(
            f"chart patch values have shape {y.shape}, expected (photos, {CHART_PATCHES}, 3)",
            f"give {CHART_PATCHES} R,G,B rows per photo, in the ColorChecker's order "
            "(dark skin … black)",
        )
    checks = (
        (~np.isfinite(y), "is missing or saturated (not a number)"),
        (y < 0, "is negative"),
        (y >= white_level if white_level is not None else np.zeros(y.shape, bool), "is saturated"),
    )
    for bad, what in checks:
        if bad.any():
            p, i, c = (int(v) for v in np.argwhere(bad)[0])
            raise RigError(
                f"photo {p + 1} patch {i + 1} channel {CHANNELS[c]} ({y[p, i, c]:g}) {what}"
                f" ({int(bad.sum())} value(s) in all)",
                "retake the photo with a shorter exposure and the chart evenly lit, and "
                "subtract the black level before averaging the patches",
            )
    dim = y.max(axis=(1, 2)) <= 0
    if dim.any():
        raise RigError(
            f"photo {int(np.argmax(dim)) + 1} has no signal (every patch is 0)",
            "check the exposure and that the lamp was on",
        )
    return y


def read_patch_csv(path: str | Path) -> np.ndarray:
    """One photo's patch values (24, 3) from a CSV of 24 ``R,G,B`` rows in the chart's order (a
    header row and ``#`` comment lines are skipped; commas, semicolons, tabs or spaces)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise RigError(
            f"cannot read patch file {path}: {error}", "give a CSV of R,G,B rows"
        ) from error
    rows: list[list[float]] = []
    header_allowed = True
    for lineno, line in enumerate(text.splitlines(), start=1):
        cells = re.split(r"[,;\s]+", line.strip())
        if not cells[0] or cells[0].startswith("#"):
            continue
        try:
            values = [float(c) for c in cells if c]
        except ValueError as error:
            if header_allowed:
                header_allowed = False
                continue
            raise RigError(
                f"{path}:{lineno}: not a row of numbers ({error})", "give R,G,B values"
            ) from error
        header_allowed = False
        if len(values) != 3:
            raise RigError(f"{path}:{lineno}: {len(values)} values", "each row holds R,G,B")
        rows.append(values)
    if len(rows) != CHART_PATCHES:
        raise RigError(
            f"{path} holds {len(rows)} patch rows",
            f"give {CHART_PATCHES} R,G,B rows, one per ColorChecker patch in the chart's order "
            "(dark skin … black)",
        )
    return np.array(rows)


def fit_camera(
    patch_rgb: np.ndarray,
    lamp_spds: np.ndarray,
    reflectances: np.ndarray,
    prior: SensitivityPrior,
    noise: PatchNoise | None = None,
    *,
    white_level: float | None = None,
    max_evaluations: int = 1000,
) -> CameraFit:
    """Estimate a camera's sensitivity from chart patch values.

    ``patch_rgb`` (P, 24, 3) linear camera RGB, black subtracted, any scale; ``lamp_spds``
    (P, N_λ) the lamp of each photo (or (N_λ,) for all) on the prior's grid, any scale;
    ``reflectances`` (24, N_λ) of the chart's patches in the same order.
    """
    noise = noise or PatchNoise()
    y = validate_patches(patch_rgb, white_level)
    n_photos = y.shape[0]
    n_wl = prior.mean.shape[0]
    lamps = np.atleast_2d(np.asarray(lamp_spds, dtype=float))
    if lamps.shape[0] == 1:
        lamps = np.repeat(lamps, n_photos, axis=0)
    refl = np.asarray(reflectances, dtype=float)
    if lamps.shape != (n_photos, n_wl) or refl.shape != (CHART_PATCHES, n_wl):
        raise RigError(
            f"{n_photos} photo(s) with lamp SPDs {lamps.shape} and chart reflectances "
            f"{refl.shape} on a grid of {n_wl} wavelengths",
            f"give one lamp SPD per photo (or one for all) and {CHART_PATCHES} reflectances, "
            "all on the prior's grid",
        )
    if not (np.all(np.isfinite(lamps)) and np.all(lamps >= 0) and np.all(lamps.sum(1) > 0)):
        raise RigError("a lamp SPD is zero, negative or not finite", "check the lamp's store entry")
    # each photo in units of its brightest patch so one noise model fits every exposure
    photo_scale = y.max(axis=(1, 2))
    yn = y / photo_scale[:, None, None]
    weight = 1.0 / noise.sigma(yn)
    design = refl[None] * lamps[:, None, :]  # (P, 24, N_λ)
    solution = _solve(design, yn, weight, prior, max_evaluations)
    if solution.status == 0:
        raise RigError(
            f"the chart fit did not converge in {max_evaluations} evaluations",
            "check that each photo's lamp is the one named for it and that the patches are in "
            "the chart's order",
        )
    s = solution.x[: 3 * n_wl].reshape(3, n_wl).T
    exposure = np.exp(solution.x[3 * n_wl : 3 * n_wl + n_photos])
    slopes = solution.x[3 * n_wl + n_photos :].reshape(2, n_photos).T
    shading = 1.0 + slopes @ chart_coordinates().T
    covariance = np.linalg.pinv(solution.jac.T @ solution.jac)
    post_std = np.sqrt(np.diag(covariance)[: 3 * n_wl]).reshape(3, n_wl).T
    peak = float(s.max())
    predicted = np.einsum("pin,nc->pic", design, s) * (exposure[:, None] * shading)[:, :, None]
    return CameraFit(
        sensitivity=s / peak,
        posterior_std=post_std / peak,
        exposure=exposure * peak * photo_scale,
        shading=shading,
        predicted=predicted * photo_scale[:, None, None],
        observed=y,
        prior_distance=_prior_distance(prior, s / peak),
        training_distances=np.array(
            [_prior_distance(prior, t) for t in prior.training.sensitivities]
        ),
        evaluations=int(solution.nfev),
        prior=prior,
    )


def chart_coordinates() -> np.ndarray:
    """Each patch's centre (24, 2) as (column, row) in patch pitches from the chart's centre:
    the classic chart's 4 rows of 6, in reading order."""
    index = np.arange(CHART_PATCHES)
    return np.column_stack([index % 6 - 2.5, index // 6 - 1.5])


def _solve(
    design: np.ndarray,
    yn: np.ndarray,
    weight: np.ndarray,
    prior: SensitivityPrior,
    max_evaluations: int,
) -> OptimizeResult:
    """The MAP estimate by bounded Gauss-Newton (trust region reflective), from the prior's mean
    and the exposures that fit it best. The unknowns: S channel by channel (3 N_λ), then per
    photo log k (exposures stay positive), then the light's slope across the chart along the
    columns and the rows (P each)."""
    n_photos, _, n_wl = design.shape
    ns = 3 * n_wl
    whitening = np.zeros((ns, ns))
    for c in range(3):
        whitening[c * n_wl : (c + 1) * n_wl, c * n_wl : (c + 1) * n_wl] = prior.whitening(c)
    mean = prior.mean.T.ravel()
    uv = chart_coordinates()

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """S (N_λ, 3), k (P,), the unshaded prediction (P, 24, 3) and the shading (P, 24)."""
        s = x[:ns].reshape(3, n_wl).T
        k = np.exp(x[ns : ns + n_photos])
        slopes = x[ns + n_photos :].reshape(2, n_photos).T
        shading = k[:, None] * (1.0 + slopes @ uv.T)
        return s, k, np.einsum("pin,nc->pic", design, s), shading

    def residuals(x: np.ndarray) -> np.ndarray:
        _, _, base, shading = unpack(x)
        data = weight * (base * shading[:, :, None] - yn)
        return np.concatenate([data.ravel(), whitening @ (x[:ns] - mean)])

    def jacobian(x: np.ndarray) -> np.ndarray:
        _, k, base, shading = unpack(x)
        jac = np.zeros((yn.size + ns, x.size))
        data = jac[: yn.size].reshape(n_photos, CHART_PATCHES, 3, x.size)
        for c in range(3):
            block = (weight[:, :, c] * shading)[:, :, None] * design
            data[:, :, c, c * n_wl : (c + 1) * n_wl] = block
        for p in range(n_photos):
            data[p, :, :, ns + p] = weight[p] * base[p] * shading[p, :, None]
            for axis in range(2):
                column = ns + (1 + axis) * n_photos + p
                data[p, :, :, column] = weight[p] * base[p] * (k[p] * uv[:, axis])[:, None]
        jac[yn.size :, :ns] = whitening
        return jac

    pred0 = np.einsum("pin,nc->pic", design, prior.mean)
    k0 = np.sum(weight**2 * pred0 * yn, axis=(1, 2)) / np.sum(weight**2 * pred0**2, axis=(1, 2))
    x0 = np.concatenate([np.clip(mean, 1e-9, None), np.log(k0), np.zeros(2 * n_photos)])
    # slopes bounded so the light stays positive over the whole chart
    lower = np.concatenate(
        [
            np.zeros(ns),
            np.full(n_photos, -np.inf),
            np.full(n_photos, -0.19),
            np.full(n_photos, -0.33),
        ]
    )
    upper = np.concatenate(
        [np.full(ns + n_photos, np.inf), np.full(n_photos, 0.19), np.full(n_photos, 0.33)]
    )
    return least_squares(
        residuals,
        x0,
        jac=jacobian,
        bounds=(lower, upper),
        method="trf",
        x_scale="jac",
        max_nfev=max_evaluations,
    )


def _prior_distance(prior: SensitivityPrior, curves: np.ndarray) -> np.ndarray:
    """Mahalanobis distance per channel, divided by √N_λ (≈ 1 for a typical draw)."""
    n = curves.shape[0]
    return np.array(
        [
            np.linalg.norm(prior.whitening(c) @ (curves[:, c] - prior.mean[:, c])) / np.sqrt(n)
            for c in range(3)
        ]
    )


def simulate_patches(
    sensitivity: np.ndarray, lamp_spds: np.ndarray, reflectances: np.ndarray
) -> np.ndarray:
    """Noise-free chart patch values (P, 24, 3) of a camera under each lamp (P, N_λ), each photo
    exposed so its brightest patch reads 1."""
    lamps = np.atleast_2d(np.asarray(lamp_spds, dtype=float))
    y = np.einsum("in,pn,nc->pic", np.asarray(reflectances), lamps, np.asarray(sensitivity))
    return np.asarray(y / y.max(axis=(1, 2), keepdims=True))
