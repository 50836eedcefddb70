"""The prior of a camera's spectral sensitivity: measured cameras (a camspec file or folder of
Jiang et al.'s database, or the cameras already in a calibration store; nothing is bundled),
each normalised as the store keeps them (maximum over channels and wavelengths = 1), and per
channel their mean, first principal components and the variance a camera left out of the set
shows (probabilistic PCA), which :func:`calibration.camera_fit.fit_camera` fits under.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibration.grid import DEFAULT_GRID, SpectralGrid
from calibration.spectra import resample
from calibration.store import CalibrationStore
from core.errors import RigError

CAMSPEC_WAVELENGTHS = np.arange(400.0, 721.0, 10.0)
"""The camspec database's sampling: 400–720 nm in 10 nm steps (33 values per channel)."""
DEFAULT_COMPONENTS = 4
MIN_TRAINING_CAMERAS = 5
CHART_FIT_METHOD = "chart-fit"
"""The ``method`` a store entry's provenance names when it was estimated by :func:`fit_camera`."""


# -- training set -------------------------------------------------------------------------------
@dataclass(frozen=True)
class TrainingSet:
    """Measured sensitivities ``(M, N_λ, 3)`` on ``grid``, each normalised to a maximum of 1."""

    names: list[str]
    sensitivities: np.ndarray
    grid: SpectralGrid
    source: str

    def without(self, name: str) -> TrainingSet:
        """The set less the camera ``name`` (leave-one-out)."""
        keep = [i for i, n in enumerate(self.names) if n != name]
        return TrainingSet(
            [self.names[i] for i in keep],
            self.sensitivities[keep],
            self.grid,
            f"{self.source} less {name}",
        )

    def sensitivity(self, name: str) -> np.ndarray:
        return np.asarray(self.sensitivities[self.names.index(name)])


def _normalised(curves: np.ndarray) -> np.ndarray:
    return curves / np.max(curves, axis=(1, 2), keepdims=True)


def _camspec_files(path: Path) -> list[Path]:
    if path.is_dir():
        files = sorted(path.glob("*.txt"))
        if not files:
            raise RigError(
                f"{path} holds no camspec .txt file",
                "name a file or folder of the camspec database (a name line, then R, G, B "
                "lines of 33 values, 400–720 nm)",
            )
        return files
    if not path.is_file():
        raise RigError(f"camera training set {path} does not exist", "give the file or folder")
    return [path]


def read_camspec(path: str | Path, grid: SpectralGrid = DEFAULT_GRID) -> TrainingSet:
    """Sensitivities in the camspec format (Jiang et al.'s database: per camera a name line,
    then R, G and B lines of 33 values at 400–720 nm; ``#`` lines are comments) from a file or
    every ``*.txt`` in a folder, resampled onto ``grid``."""
    names: list[str] = []
    curves: list[np.ndarray] = []
    for file in _camspec_files(Path(path)):
        lines = [
            (n, ln.strip())
            for n, ln in enumerate(file.read_text(encoding="utf-8").splitlines(), start=1)
            if ln.strip() and not ln.lstrip().startswith("#")
        ]
        if len(lines) % 4:
            raise RigError(
                f"{file}: {len(lines)} non-comment lines, not a whole number of cameras",
                "each camera is a name line followed by R, G and B lines",
            )
        for start in range(0, len(lines), 4):
            lineno, name = lines[start]
            rows = []
            for n, text in lines[start + 1 : start + 4]:
                try:
                    values = [float(x) for x in text.replace(",", " ").split()]
                except ValueError as error:
                    raise RigError(
                        f"{file}:{n}: not a row of numbers ({error})",
                        f"camera {name!r} (line {lineno}) needs R, G and B lines of 33 values",
                    ) from error
                if len(values) != CAMSPEC_WAVELENGTHS.size:
                    raise RigError(
                        f"{file}:{n}: {len(values)} values for camera {name!r}",
                        "camspec rows hold 33 values, 400–720 nm in 10 nm steps",
                    )
                rows.append(values)
            native = np.array(rows).T
            curves.append(resample(CAMSPEC_WAVELENGTHS, native, grid, source=f"{file} {name}"))
            names.append(name)
    return _checked(TrainingSet(names, _normalised(np.stack(curves)), grid, str(path)))


def training_set_from_store(
    store: CalibrationStore, grid: SpectralGrid = DEFAULT_GRID, exclude: tuple[str, ...] = ()
) -> TrainingSet:
    """The latest version of every *measured* camera in ``store`` (less ``exclude``) as a
    training set: cameras estimated from a chart (provenance ``method: chart-fit``) are left out,
    so estimates never become the prior of the next estimate."""
    names = [
        e.name
        for e in store.entries("camera", all_versions=False)
        if e.name not in exclude and e.provenance.get("method") != CHART_FIT_METHOD
    ]
    curves = [store.camera(n, grid) for n in names]
    if len(curves) < MIN_TRAINING_CAMERAS:
        raise RigError(
            f"the calibration store {store.root} holds {len(curves)} camera(s) to learn the "
            f"prior from; at least {MIN_TRAINING_CAMERAS} are needed",
            "pass --prior with a file or folder of measured sensitivities (camspec format, e.g. "
            "Jiang et al.'s database)",
        )
    return _checked(TrainingSet(names, _normalised(np.stack(curves)), grid, f"store {store.root}"))


def _checked(training: TrainingSet) -> TrainingSet:
    if len(training.names) < MIN_TRAINING_CAMERAS:
        raise RigError(
            f"camera training set {training.source} holds {len(training.names)} camera(s)",
            f"the prior needs at least {MIN_TRAINING_CAMERAS} measured sensitivities",
        )
    return training


# -- prior --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SensitivityPrior:
    """A Gaussian over each channel's curve: ``mean`` (N_λ, 3); per channel c the principal
    directions ``components[c]`` (N_λ, K) with variances ``variances[c]`` (K,), and
    ``residual_variance[c]`` along every other direction."""

    mean: np.ndarray
    components: np.ndarray
    variances: np.ndarray
    residual_variance: np.ndarray
    training: TrainingSet

    @property
    def n_components(self) -> int:
        return int(self.components.shape[2])

    def whitening(self, channel: int) -> np.ndarray:
        """Σ_c^{-1/2} (N_λ, N_λ): ‖Σ^{-1/2}(s − mean)‖² is the prior's energy."""
        u = self.components[channel]
        outside = np.eye(u.shape[0]) - u @ u.T
        inside = u @ np.diag(self.variances[channel] ** -0.5) @ u.T
        return np.asarray(inside + outside / np.sqrt(self.residual_variance[channel]))

    def std(self) -> np.ndarray:
        """The prior's standard deviation per wavelength and channel (N_λ, 3)."""
        out = np.empty_like(self.mean)
        for c in range(3):
            u = self.components[c]
            var = np.einsum("nk,k,nk->n", u, self.variances[c], u)
            var += self.residual_variance[c] * (1.0 - np.einsum("nk,nk->n", u, u))
            out[:, c] = np.sqrt(var)
        return out


def build_prior(training: TrainingSet, n_components: int = DEFAULT_COMPONENTS) -> SensitivityPrior:
    """The Gaussian prior of a training set: PCA per channel with ``n_components`` components
    (Jiang et al. use 2) and, along every other direction, the variance a held-out camera
    shows (module docstring)."""
    curves = training.sensitivities
    m, n, _ = curves.shape
    if not 1 <= n_components < min(m - 1, n):
        raise RigError(
            f"{n_components} prior components for {m} training cameras",
            f"use 1 to {min(m - 1, n) - 1} components (default {DEFAULT_COMPONENTS})",
        )
    mean = curves.mean(axis=0)
    comps, variances, residual = [], [], []
    for c in range(3):
        u, eig = _principal(curves[:, :, c], n_components)
        comps.append(u)
        variances.append(eig)
        # floored so a direction no camera varies in is unlikely, not forbidden
        held_out = _held_out_residual_variance(curves[:, :, c], n_components)
        residual.append(max(held_out, 1e-6 * float(eig[0])))
    return SensitivityPrior(
        mean, np.stack(comps), np.stack(variances), np.array(residual), training
    )


def _principal(x: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The first ``k`` principal directions (N, k) of rows ``x`` and their variances (k,)."""
    _, sv, vt = np.linalg.svd(x - x.mean(axis=0), full_matrices=False)
    return vt[:k].T, sv[:k] ** 2 / (x.shape[0] - 1)


def _held_out_residual_variance(x: np.ndarray, k: int) -> float:
    """The variance per direction outside the principal subspace that a camera *not* in the
    set shows: each camera's residual from the subspace and mean of the others, averaged.
    The in-sample residual would be smaller, and a prior that tight rejects new cameras."""
    m, n = x.shape
    total = 0.0
    for i in range(m):
        rest = np.delete(x, i, axis=0)
        u, _ = _principal(rest, k)
        d = x[i] - rest.mean(axis=0)
        total += float(np.sum((d - u @ (u.T @ d)) ** 2))
    return total / (m * (n - k))
