"""What calibrating without a spectrometer costs in colour (docs/first-scan.md, Calibrate).

The reconstruction's spectra start from, and are tied by its spectral term to, the per-pixel
estimate from the RGB under each illumination through the calibrated camera and light SPDs.
This benchmark takes the 24 ColorChecker reflectances, renders their exact RGB (no noise, unit
shading) with the *true* camera and lamps from measured data, and estimates them back with the
calibration a user without a spectrometer has — each light's scale set from a white reference
photographed with the rig, as `rig calibrate wizard` does — reporting CIEDE2000 under D65 of
the estimate against the truth:

* lights: pairs of measured LED lamps (a cool and a warm white, like a bulb's c and w
  channels) estimated with (a) their own SPDs, (b) the published SPD of another lamp of the
  same nominal colour temperature, (c) the store's built-in bulb models LED1 / LED2;
* camera: each of the 27 measured cameras under the built-in LED1 / LED2, estimated with
  (a) its own sensitivity, (b) the built-in Canon EOS 5D Mark II, (c) the mean of the other 26.

    python -m bench.calibration_costs [--data ../shared/data]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from bench.external_scene import CAMSPEC_TXT, DATA, camera_ssf, data_file, lamp_spd
from calibration import defaults
from calibration.basis import default_basis
from calibration.colour_difference import delta_e00, illuminant
from calibration.estimation import estimate_reflectance, response_matrices

# (cool, warm) lamp pairs and, for each, a stand-in pair of other lamps with the same nominal
# colour temperatures: what a datasheet or a published measurement of a similar bulb gives.
LAMP_PAIRS = {
    ("Airam.LED.11W.4000K", "Osram.LED.10W.2700K"): ("Ledstore.LED.10W.4000K",
                                                    "Ikea.LED.6.3W.2700K"),
    ("Ledstore.LED.10W.4000K", "Ikea.LED.6.3W.2700K"): ("Airam.LED.11W.4000K",
                                                       "Toshiba.LED.12W.2700K"),
    ("Philips.LED.T8.10W.840", "Toshiba.LED.12W.2700K"): ("Ledenergie.LED.Teho.T8.9W.4000K",
                                                         "Osram.LED.8W.2700K"),
    ("Ledenergie.LED.Teho.T8.9W.4000K", "Osram.LED.8W.2700K"): ("Philips.LED.T8.10W.840",
                                                               "Osram.LED.10W.2700K"),
}
WHITE = 0.99  # the white reference's reflectance


def estimate_error(
    truth: np.ndarray,
    camera: np.ndarray,
    lamps: list[np.ndarray],
    assumed_camera: np.ndarray,
    assumed_lamps: list[np.ndarray],
) -> np.ndarray:
    """ΔE00 (D65) per reflectance of ``truth`` (P, N_λ) rendered with ``camera``/``lamps`` and
    estimated with the assumed ones, each assumed lamp scaled so the white reference reads
    what the true rig reads (least squares over its three channels)."""
    true_resp = response_matrices(camera, lamps)
    resp = response_matrices(assumed_camera, assumed_lamps)
    white = np.full(truth.shape[1], WHITE)
    measured, predicted = true_resp @ white, resp @ white  # (K, 3)
    scale = np.sum(measured * predicted, axis=1) / np.sum(predicted * predicted, axis=1)
    rgb = np.einsum("knl,pl->pkn", true_resp, truth)
    _, estimate = estimate_reflectance(rgb, resp * scale[:, None, None], default_basis())
    return delta_e00(estimate, truth, illuminant("D65"))


def camera_names(data: Path) -> list[str]:
    lines = [ln.strip() for ln in data_file(data, CAMSPEC_TXT).read_text().splitlines()]
    lines = [ln for ln in lines if ln and not ln.startswith("#")]
    return lines[::4]


def summary(errors: list[np.ndarray]) -> tuple[str, str, str]:
    values = np.concatenate(errors)
    return f"{values.mean():.2f}", f"{np.percentile(values, 90):.2f}", f"{values.max():.2f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA, help="the shared data folder")
    args = parser.parse_args(argv)
    _, truth = defaults.colorchecker_reflectances()
    canon = defaults.camera_sensitivity("Canon EOS 5D Mark II")
    channels = defaults.rgbcw_channel_spds()
    models = [defaults.illumination_spd(defaults.default_illuminations()[k], channels)
              for k in ("LED1", "LED2")]
    rows: list[tuple[str, ...]] = []

    own, similar, model = [], [], []
    for pair, stand_in in LAMP_PAIRS.items():
        lamps = [lamp_spd(args.data, name) for name in pair]
        others = [lamp_spd(args.data, name) for name in stand_in]
        own.append(estimate_error(truth, canon, lamps, canon, lamps))
        similar.append(estimate_error(truth, canon, lamps, canon, others))
        model.append(estimate_error(truth, canon, lamps, canon, models))
    n = f"{len(LAMP_PAIRS)} lamp pairs"
    rows.append(("lights", "measured SPDs (spectrometer)", *summary(own), n))
    rows.append(("lights", "published SPD of another lamp of the same CCT", *summary(similar), n))
    rows.append(("lights", "built-in bulb models LED1/LED2", *summary(model), n))

    names = camera_names(args.data)
    cameras = {name: camera_ssf(args.data, name) for name in names}
    own, builtin, mean = [], [], []
    for name, ssf in cameras.items():
        rest = np.mean([c for other, c in cameras.items() if other != name], axis=0)
        own.append(estimate_error(truth, ssf, models, ssf, models))
        builtin.append(estimate_error(truth, ssf, models, canon, models))
        mean.append(estimate_error(truth, ssf, models, rest, models))
    n = f"{len(names)} cameras"
    rows.append(("camera", "its measured sensitivity", *summary(own), n))
    rows.append(("camera", "built-in Canon EOS 5D Mark II", *summary(builtin), n))
    rows.append(("camera", "mean of the other cameras", *summary(mean), n))

    table = Table(title="ColorChecker 24, exact RGB: ΔE00 (D65) of the 2-D estimate")
    for column in ("calibrated", "with", "mean", "p90", "max", "over"):
        table.add_column(column)
    for row in rows:
        table.add_row(*row)
    Console().print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
