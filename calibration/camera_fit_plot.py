"""The plot of a camera sensitivity fitted from chart photos (calibration.camera_fit): the
estimate with its uncertainty against the prior's spread, and the residual of every patch."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibration.camera_fit import CameraFit
from calibration.plots import RGB_COLOURS, _save, plt


def plot_camera_fit(fit: CameraFit, wavelengths: np.ndarray, title: str, path: str | Path) -> Path:
    """Left: the estimate (±2σ of the fit, shaded) over the prior's mean ±2 sd (dashed, light);
    right: the residual per patch and photo in % of the photo's brightest patch."""
    fig, (curves, patches) = plt.subplots(1, 2, figsize=(11, 4), width_ratios=(1.1, 1))
    prior_mean = fit.prior.mean / fit.prior.mean.max()
    prior_sd = fit.prior.std() / fit.prior.mean.max()
    for c, colour in enumerate(RGB_COLOURS):
        curves.fill_between(
            wavelengths,
            np.clip(prior_mean[:, c] - 2 * prior_sd[:, c], 0, None),
            prior_mean[:, c] + 2 * prior_sd[:, c],
            color=colour,
            alpha=0.08,
            lw=0,
        )
        curves.plot(wavelengths, prior_mean[:, c], color=colour, ls="--", lw=0.8, alpha=0.6)
        est, sd = fit.sensitivity[:, c], fit.posterior_std[:, c]
        curves.fill_between(
            wavelengths, np.clip(est - 2 * sd, 0, None), est + 2 * sd, color=colour, alpha=0.3
        )
        curves.plot(wavelengths, est, color=colour, lw=1.8, label="RGB"[c])
    curves.plot([], [], color="0.4", ls="--", lw=0.8, label="prior mean ±2 sd")
    curves.set_xlabel("wavelength (nm)")
    curves.set_ylabel("sensitivity (max 1)")
    curves.set_title(
        f"estimate ±2σ; prior: {len(fit.prior.training.names)} cameras, "
        f"{fit.prior.n_components} components",
        fontsize=9,
    )
    curves.legend(fontsize=8)
    curves.grid(alpha=0.3)
    err = fit.patch_error_percent()
    n_photos = err.shape[0]
    width = 0.8 / n_photos
    index = np.arange(err.shape[1])
    for p in range(n_photos):
        patches.bar(index + p * width, err[p], width, label=f"photo {p + 1}")
    patches.set_xticks(index + 0.4 - width / 2, [str(i + 1) for i in index], fontsize=7)
    patches.set_xlabel("chart patch")
    patches.set_ylabel("RMS residual over R, G, B (% of brightest)")
    patches.set_title("fit residual per patch", fontsize=9)
    if n_photos > 1:
        patches.legend(fontsize=8)
    patches.grid(alpha=0.3, axis="y")
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)
