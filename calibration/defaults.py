"""Built-in spectra that come with colour-science (nothing is downloaded at run time).

* Camera sensitivities: the Canon EOS 5D Mark II (the paper's camera, from colour-science's
  rawtoaces dataset), Nikon 5100 and Sigma SD Merrill (colour-science's NPL measurements).
  Normalised so the maximum over channels and wavelengths is 1.
* RGBCW bulb channels: *models*, not measurements — colour-science's Ohno (2005) LED model
  (:func:`colour.sd_multi_leds`) with the parameters in :data:`BULB_CHANNEL_MODELS`; the white
  channels are a blue pump plus a broad phosphor band. Scaled by the radiometric convention
  (docs/architecture.md, Radiometry): a perfect white reflector facing the bulb at 0.5 m with every
  channel at level 1 gives 0.5 in the brightest channel of the default camera.
* Reflectances: ColorChecker 24 (BabelColor average) and rawtoaces' 190 training patches.
* CIE illuminants for relighting (:data:`colour.SDS_ILLUMINANTS`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass

import colour
import numpy as np
from colour.characterisation.aces_it import ROOT_RESOURCES_RAWTOACES

from calibration.grid import DEFAULT_GRID, SpectralGrid
from calibration.spectra import resample
from core.errors import RigError

DEFAULT_CAMERA = "Canon EOS 5D Mark II"

_CAMERAS: dict[str, str] = {
    "Canon EOS 5D Mark II": "rawtoaces:CANON_EOS_5DMark_II_RGB_Sensitivities.csv",
    "Nikon 5100": "colour:Nikon 5100 (NPL)",
    "Sigma SD Merrill": "colour:Sigma SDMerill (NPL)",
}


@dataclass(frozen=True)
class LedModel:
    """One bulb channel: Ohno (2005) LED bands (peak nm, full width nm, relative peak power)."""

    peaks_nm: tuple[float, ...]
    widths_nm: tuple[float, ...]
    ratios: tuple[float, ...]

    def describe(self) -> str:
        bands = ", ".join(
            f"{p:g} nm/{w:g} nm×{r:g}"
            for p, w, r in zip(self.peaks_nm, self.widths_nm, self.ratios, strict=True)
        )
        return f"model: colour.sd_multi_leds (Ohno 2005) bands peak/width×ratio = {bands}"


BULB_CHANNEL_MODELS: dict[str, LedModel] = {
    "r": LedModel((625.0,), (20.0,), (1.0,)),
    "g": LedModel((525.0,), (35.0,), (1.0,)),
    "b": LedModel((455.0,), (22.0,), (1.0,)),
    "c": LedModel((450.0, 555.0), (20.0, 110.0), (1.0, 0.55)),  # cool white ~6000 K
    "w": LedModel((450.0, 600.0), (20.0, 130.0), (0.3, 1.0)),  # warm white ~3000 K
}
"""Typical RGBCW smart-bulb channels; each is scaled to the same radiant power before the
common radiometric scale is applied."""

REFERENCE_DISTANCE_M = 0.5
REFERENCE_SIGNAL = 0.5


def camera_names() -> list[str]:
    """Names accepted by :func:`camera_sensitivity`."""
    return list(_CAMERAS)


def _camera_source(name: str) -> str:
    for key, src in _CAMERAS.items():
        if name.strip().lower() in (key.lower(), src.split(":", 1)[1].lower()):
            return src
    raise RigError(
        f"unknown built-in camera {name!r}",
        f"choose one of {', '.join(_CAMERAS)} or import a measured sensitivity "
        "(rig calibrate import FILE --kind camera)",
    )


def camera_source_description(name: str) -> str:
    """Where a built-in camera sensitivity comes from (for provenance)."""
    src = _camera_source(name)
    kind, ref = src.split(":", 1)
    if kind == "rawtoaces":
        return f"colour-science {colour.__version__} rawtoaces dataset {ref}"
    return f"colour-science {colour.__version__} colour.MSDS_CAMERA_SENSITIVITIES[{ref!r}]"


def camera_sensitivity_native(name: str = DEFAULT_CAMERA) -> tuple[np.ndarray, np.ndarray]:
    """A built-in camera's sensitivity at its native sampling: (wavelengths (M,), RGB (M, 3))."""
    kind, ref = _camera_source(name).split(":", 1)
    if kind == "rawtoaces":
        sds = colour.io.read_sds_from_csv_file(os.path.join(ROOT_RESOURCES_RAWTOACES, ref))
        msds = colour.colorimetry.sds_and_msds_to_msds(list(sds.values()))
    else:
        msds = colour.MSDS_CAMERA_SENSITIVITIES[ref]
    values = np.asarray(msds.values, dtype=float)
    return np.asarray(msds.wavelengths, dtype=float), values / values.max()


def camera_sensitivity(name: str = DEFAULT_CAMERA, grid: SpectralGrid = DEFAULT_GRID) -> np.ndarray:
    """Built-in camera sensitivity C on ``grid``, shape (N_λ, 3) (R, G, B), max 1.

    The Sigma data stops at 680 nm; it is extended with colour-science's constant extrapolation.
    """
    w, rgb = camera_sensitivity_native(name)
    c = resample(w, rgb, grid, source=f"built-in camera {name}", extrapolate=True)
    return c / c.max()


def _unit_channel(model: LedModel, grid: SpectralGrid) -> np.ndarray:
    shape = colour.SpectralShape(360, 780, 1)
    sd = colour.sd_multi_leds(
        np.array(model.peaks_nm),
        half_spectral_widths=np.array(model.widths_nm),
        peak_power_ratios=np.array(model.ratios),
        shape=shape,
    )
    spd = resample(sd.wavelengths, sd.values, grid, source="LED model")
    return spd / spd.sum()


def radiometric_scale(
    full_spd: np.ndarray, camera: np.ndarray, distance_m: float = REFERENCE_DISTANCE_M
) -> float:
    """Factor that makes a white reflector at ``distance_m`` read :data:`REFERENCE_SIGNAL`."""
    signal = float(np.max(camera.T @ full_spd)) / distance_m**2
    return REFERENCE_SIGNAL / signal


def rgbcw_channel_spds(
    grid: SpectralGrid = DEFAULT_GRID, camera: str = DEFAULT_CAMERA
) -> dict[str, np.ndarray]:
    """Model SPDs of the bulb's channels ``r, g, b, c, w`` on ``grid`` (radiometrically scaled)."""
    units = {k: _unit_channel(m, grid) for k, m in BULB_CHANNEL_MODELS.items()}
    full = np.sum(list(units.values()), axis=0)
    scale = radiometric_scale(full, camera_sensitivity(camera, grid))
    return {k: v * scale for k, v in units.items()}


def default_illuminations() -> dict[str, dict[str, float]]:
    """The bulb's three named illuminations (channel levels in 0..1), as in the paper's setup."""
    return {
        "LED1": {"c": 1.0},
        "LED2": {"w": 1.0},
        "LED3": {"r": 1.0, "g": 1.0, "b": 1.0},
    }


def illumination_spd(levels: Mapping[str, float], channels: Mapping[str, np.ndarray]) -> np.ndarray:
    """SPD of a channel mix: ``Σ level_k · spd_k`` (levels in 0..1)."""
    if not levels:
        raise RigError("illumination has no channel levels", "give at least one channel, e.g. c: 1")
    total: np.ndarray | None = None
    for key, level in levels.items():
        if key not in channels:
            raise RigError(
                f"illumination uses unknown channel {key!r}",
                f"use the light's channels: {', '.join(channels)}",
            )
        try:
            value = float(level)
        except (TypeError, ValueError) as error:
            raise RigError(
                f"channel {key!r} level {level!r} is not a number", "use 0..1"
            ) from error
        if not 0.0 <= value <= 1.0:
            raise RigError(
                f"channel {key!r} level {level} is outside 0..1", "use levels between 0 and 1"
            )
        term = value * np.asarray(channels[key], dtype=float)
        total = term if total is None else total + term
    assert total is not None
    return total


def colorchecker_reflectances(grid: SpectralGrid = DEFAULT_GRID) -> tuple[list[str], np.ndarray]:
    """ColorChecker 24 patch names and reflectances (24, N_λ) (BabelColor average)."""
    sds = colour.SDS_COLOURCHECKERS["BabelColor Average"]
    names = list(sds)
    values = np.stack([np.asarray(sds[n].values, dtype=float) for n in names], axis=1)
    w = np.asarray(sds[names[0]].wavelengths, dtype=float)
    return names, resample(w, values, grid, source="ColorChecker 24 (BabelColor)").T


def rawtoaces_reflectances(grid: SpectralGrid = DEFAULT_GRID) -> np.ndarray:
    """rawtoaces' 190 training patches (colour-science): (190, N_λ)."""
    msds = colour.characterisation.read_training_data_rawtoaces_v1()
    return resample(
        msds.wavelengths, msds.values, grid, source="rawtoaces 190 training patches"
    ).T


def training_reflectances(grid: SpectralGrid = DEFAULT_GRID) -> np.ndarray:
    """rawtoaces' 190 training patches plus the ColorChecker 24: (214, N_λ)."""
    return np.vstack([rawtoaces_reflectances(grid), colorchecker_reflectances(grid)[1]])


def illuminant_names() -> list[str]:
    """CIE illuminant names accepted by :func:`cie_illuminant`."""
    return list(colour.SDS_ILLUMINANTS)


def cie_illuminant(name: str = "D65", grid: SpectralGrid = DEFAULT_GRID) -> np.ndarray:
    """A CIE illuminant from colour-science on ``grid``, normalised to a maximum of 1."""
    match = next((k for k in colour.SDS_ILLUMINANTS if k.lower() == name.strip().lower()), None)
    if match is None:
        raise RigError(
            f"unknown CIE illuminant {name!r}",
            f"use one of colour.SDS_ILLUMINANTS, e.g. {', '.join(illuminant_names()[:12])}",
        )
    sd = colour.SDS_ILLUMINANTS[match]
    spd = resample(sd.wavelengths, sd.values, grid, source=f"CIE illuminant {match}")
    return spd / spd.max()
