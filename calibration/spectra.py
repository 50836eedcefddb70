"""Validation and resampling of measured spectra onto the spectral grid.

Every spectrum entering spectral-rig (a spectrometer export, a camera sensitivity table, a
colour-science dataset) goes through :func:`resample`, so one place decides what counts as a
valid spectrum and how it is brought onto the grid:

* wavelengths must be finite, in nanometres (within 100–3000 nm: a µm export is refused),
  strictly increasing (no duplicates) and cover the grid;
* values must be finite and within ±1e15; with ``nonnegative=True`` (power, sensitivity,
  reflectance) values below ``-5 %`` of the peak are an error, smaller negatives are
  dark-subtraction noise and become 0;
* interpolation is colour-science's: a :class:`colour.MultiSpectralDistributions` evaluated at
  the grid wavelengths with the interpolator its ``interpolate``/``align`` picks (Sprague 1880
  for evenly spaced data, cubic spline otherwise);
* data much denser than the grid (every step ≤ a quarter of the grid step, e.g. a spectrometer's
  0.3–1 nm pixels) is first box-averaged over
  one grid step, which is what a 10 nm-bandwidth measurement would record and keeps pixel noise
  out of the resampled spectrum;
* extrapolation happens only when asked (``extrapolate=True``) and is colour-science's constant
  extrapolation (edge value held).
"""

from __future__ import annotations

import colour
import numpy as np
import numpy.typing as npt

from calibration.grid import DEFAULT_GRID, SpectralGrid
from core.errors import RigError

NEGATIVE_TOLERANCE = 0.05
"""Negative values down to this fraction of the peak are treated as noise and clipped to 0."""

MIN_SAMPLES = 4
SPRAGUE_MIN_SAMPLES = 6  # colour's Sprague interpolator needs six; fewer take the cubic spline

WAVELENGTH_RANGE_NM = (100.0, 3000.0)
"""Wavelengths outside this are no spectrometer's (µm or Å exports, a shifted column)."""

MAX_MAGNITUDE = 1e15
"""Largest absolute value accepted: any radiometric unit or count fits, and products of such
values stay far from float64's overflow (an SPD of 1e308 made every solve singular)."""


def validate_spectrum(
    wavelengths_nm: npt.ArrayLike,
    values: npt.ArrayLike,
    *,
    source: str = "spectrum",
    nonnegative: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Check a sampled spectrum and return ``(wavelengths (M,), values (M, k))`` as floats.

    Raises :class:`RigError` naming ``source`` for every problem a measured file can have.
    Small negative values (noise) are clipped to zero when ``nonnegative``.
    """
    try:
        w = np.asarray(wavelengths_nm, dtype=float)
        v = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as error:
        raise RigError(
            f"{source}: wavelengths or values are not numbers ({error})",
            "check that every row holds numeric values",
        ) from error
    if w.ndim != 1:
        raise RigError(f"{source}: wavelengths must be one column", "give one wavelength per row")
    if v.ndim == 1:
        v = v[:, None]
    if v.ndim != 2 or v.shape[0] != w.size:
        raise RigError(
            f"{source}: {w.size} wavelengths but values of shape {v.shape}",
            "give one row of values per wavelength",
        )
    if w.size < MIN_SAMPLES:
        raise RigError(
            f"{source}: only {w.size} samples",
            f"a spectrum needs at least {MIN_SAMPLES} wavelengths",
        )
    if not np.all(np.isfinite(w)):
        raise RigError(f"{source}: wavelengths contain NaN or inf", "remove or fix those rows")
    low, high = WAVELENGTH_RANGE_NM
    if np.max(np.abs(w)) <= 10.0:
        raise RigError(
            f"{source}: wavelengths {w.min():g}–{w.max():g} look like micrometres",
            "convert them to nanometres (multiply by 1000) and import again",
        )
    if w.min() < low or w.max() > high:
        raise RigError(
            f"{source}: wavelengths {w.min():g}–{w.max():g} are outside "
            f"{low:g}–{high:g} nm",
            "give the wavelength column in nanometres",
        )
    steps = np.diff(w)
    if np.any(steps == 0):
        dup = w[1:][steps == 0][0]
        raise RigError(
            f"{source}: duplicate wavelength {dup:g} nm",
            "keep one row per wavelength (average repeated measurements first)",
        )
    if np.any(steps < 0):
        bad = w[1:][steps < 0][0]
        raise RigError(
            f"{source}: wavelengths are not increasing (at {bad:g} nm)",
            "sort the rows by wavelength",
        )
    if not np.all(np.isfinite(v)):
        row = int(np.argwhere(~np.isfinite(v))[0, 0])
        raise RigError(
            f"{source}: value is NaN or inf at {w[row]:g} nm",
            "re-export the measurement or remove the broken rows",
        )
    if np.max(np.abs(v)) > MAX_MAGNITUDE:
        row = int(np.argwhere(np.abs(v) > MAX_MAGNITUDE)[0, 0])
        raise RigError(
            f"{source}: value {v[row].max():g} at {w[row]:g} nm is outside the allowed range "
            f"±{MAX_MAGNITUDE:g}",
            "re-export the measurement in a unit that keeps values within that range",
        )
    if nonnegative:
        peak = np.max(np.abs(v), axis=0)
        if np.any(peak == 0):
            raise RigError(f"{source}: a column is all zeros", "check the measurement/export")
        low = v < -NEGATIVE_TOLERANCE * peak
        if np.any(low):
            row, col = (int(i) for i in np.argwhere(low)[0])
            raise RigError(
                f"{source}: negative power/sensitivity {v[row, col]:g} at {w[row]:g} nm "
                f"(column {col + 1})",
                "subtract the dark spectrum correctly or re-measure; only noise-level negatives "
                f"(> -{NEGATIVE_TOLERANCE:.0%} of the peak) are accepted",
            )
        v = np.clip(v, 0.0, None)
    return w, v


def _box_average(w: np.ndarray, v: np.ndarray, width: float) -> np.ndarray:
    """Average ``v`` over ``[w - width/2, w + width/2]`` at every sample (trapezoid rule)."""
    cum = np.concatenate(
        [np.zeros((1, v.shape[1])), np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(w)[:, None], 0)]
    )

    def integral(x: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(x, w, cum[:, j]) for j in range(v.shape[1])], axis=1)

    lo = np.clip(w - width / 2, w[0], w[-1])
    hi = np.clip(w + width / 2, w[0], w[-1])
    return (integral(hi) - integral(lo)) / (hi - lo)[:, None]


def _interpolate(w: np.ndarray, v: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``v`` (M, k) sampled at ``w`` evaluated at ``target`` with colour-science's interpolator.

    Uses the interpolator :meth:`colour.SpectralDistribution.interpolate` would pick (Sprague for
    evenly spaced data, cubic spline otherwise) at exactly the target wavelengths; targets outside
    ``w`` take the edge value (colour's constant extrapolation). ``align()`` is not used because,
    for data starting inside the grid, it builds its domain from the data's first wavelength and
    the grid points then fall between its samples.
    """
    msds = colour.MultiSpectralDistributions(v, w, labels=[f"c{j}" for j in range(v.shape[1])])
    uniform = msds.is_uniform() and w.size >= SPRAGUE_MIN_SAMPLES
    msds.interpolator = colour.SpragueInterpolator if uniform else colour.CubicSplineInterpolator
    return np.asarray(msds[np.clip(target, w[0], w[-1])], dtype=float).reshape(target.size, -1)


def resample(
    wavelengths_nm: npt.ArrayLike,
    values: npt.ArrayLike,
    grid: SpectralGrid = DEFAULT_GRID,
    *,
    source: str = "spectrum",
    nonnegative: bool = True,
    extrapolate: bool = False,
    band_average: bool = True,
) -> np.ndarray:
    """Resample a spectrum onto ``grid`` with colour-science.

    ``values`` of shape (M,) gives (N_λ,); (M, k) gives (N_λ, k). ``source`` names the file or
    store entry in error messages. ``band_average=False`` turns off the box average of dense
    data (for tabulated functions such as colour-matching functions that must be point-sampled).
    See the module docstring for the rules.
    """
    w, v = validate_spectrum(wavelengths_nm, values, source=source, nonnegative=nonnegative)
    squeeze = np.ndim(values) == 1
    target = grid.wavelengths
    tol = 1e-6
    if not extrapolate and (w[0] > target[0] + tol or w[-1] < target[-1] - tol):
        raise RigError(
            f"{source}: covers {w[0]:g}–{w[-1]:g} nm but the grid needs "
            f"{target[0]:g}–{target[-1]:g} nm",
            "measure/export the full range, or choose a narrower grid in the profile",
        )
    if band_average and float(np.max(np.diff(w))) <= grid.step_nm / 4:
        v = _box_average(w, v, grid.step_nm)
    if w.size == target.size and np.allclose(w, target):
        out = v.copy()
    else:
        out = _interpolate(w, v, target)
    if nonnegative:
        out = np.clip(out, 0.0, None)  # interpolation ringing around narrow LED peaks
    return out[:, 0] if squeeze else out


def second_difference_matrix(n: int) -> np.ndarray:
    """The (n-2, n) second-difference operator D: ``(D r)_i = r_i - 2 r_{i+1} + r_{i+2}``.

    Only interior rows are kept, so a straight line (any constant or linear spectrum) has zero
    penalty; this is the paper's spectral smoothness operator (eq. 8) without boundary rows.
    """
    if n < 3:
        raise RigError(f"second difference needs at least 3 samples, got {n}", "use a finer grid")
    d = np.zeros((n - 2, n))
    idx = np.arange(n - 2)
    d[idx, idx] = 1.0
    d[idx, idx + 1] = -2.0
    d[idx, idx + 2] = 1.0
    return d
