"""A camera's sensitivity from ColorChecker photos, leave-one-camera-out over the 27 measured
cameras of Jiang et al.'s database (``../shared/data/camera_ssf``).

For each held-out camera: the chart's 24 patches (BabelColor average reflectances) simulated
under one and under two measured lamps (``../shared/data/spd``), with sensor noise (shot and read
noise of a patch averaged over ``--pixels`` pixels, the white patch at 60 % of the full well) and,
in a second case, also a 1 % error per patch and channel (the printed chart against its reference
data, the lamp against its measurement), in a third also a light sloping across the chart;
fitted with :func:`calibration.camera_fit.fit_camera` under a prior from the other 26 cameras,
``--seeds`` noise draws each. Scored by the RMSE and the angle between the fitted and the true
curves (each normalised to a maximum of 1), and by the ΔE00 (D65 and A) it causes downstream:
the 1269 Munsell chips (none of them a chart patch) seen by the true camera under the project's
three default illuminations, their reflectances estimated
(:func:`calibration.estimation.estimate_reflectance`) with the fitted and with the true
sensitivity, after the white-reference scaling the wizard does (a white patch reads the same).

    python -m bench.camera_from_chart
    python -m bench.camera_from_chart --quick      # 3 cameras, 1 seed
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from bench._common import ResultTable, machine_info, make_console, report
from bench.external_scene import CAMSPEC_TXT, DATA, LAMPS_CSV, data_file
from calibration import defaults
from calibration.basis import default_basis
from calibration.camera_fit import chart_coordinates, fit_camera, simulate_patches
from calibration.camera_prior import DEFAULT_COMPONENTS, TrainingSet, build_prior, read_camspec
from calibration.colour_difference import DEFAULT_ILLUMINANTS, delta_e00, illuminant
from calibration.estimation import estimate_reflectance, response_matrices
from calibration.grid import DEFAULT_GRID
from calibration.importers import read_reflectance_set, read_spectrum
from calibration.spectra import resample

MUNSELL_CSV = "reflectance/munsell_matt_1269_380_780_5nm.csv"
LAMPS = ("Amaran.M9.LED.video.light.5500K", "Generic.Inc.bulb.60W")
FULL_WELL_E = 20000.0
READ_NOISE_E = 4.0
WHITE_FILL = 0.6
CHART_ERROR = 0.01
UNEVEN_SLOPE = 0.06
NOISE_CASES = ("sensor", "sensor + 1 % chart", "sensor + 1 % chart + uneven light")


@dataclass(frozen=True)
class Scene:
    """What every held-out camera is scored with."""

    lamps: np.ndarray  # (2, N_λ)
    chart: np.ndarray  # (24, N_λ)
    munsell: np.ndarray  # (M, N_λ)
    rig_lights: np.ndarray  # (3, N_λ): the default LED1..3
    pixels: int


def load_scene(data: Path, pixels: int) -> Scene:
    table = read_spectrum(data_file(data, LAMPS_CSV))
    lamps = np.stack(
        [
            resample(table.wavelengths_nm, table.column(n, "light"), DEFAULT_GRID, source=n)
            for n in LAMPS
        ]
    )
    _, w, values = read_reflectance_set(data_file(data, MUNSELL_CSV))
    munsell = resample(w, values.T, DEFAULT_GRID, source=MUNSELL_CSV).T
    channels = defaults.rgbcw_channel_spds(DEFAULT_GRID)
    rig = np.stack(
        [defaults.illumination_spd(v, channels) for v in defaults.default_illuminations().values()]
    )
    chart = defaults.colorchecker_reflectances(DEFAULT_GRID)[1]
    return Scene(lamps, chart, munsell, rig, pixels)


def noisy_patches(
    truth: np.ndarray, lamps: np.ndarray, scene: Scene, case: str, rng: np.random.Generator
) -> np.ndarray:
    """Patch means in electrons: shot and read noise of ``scene.pixels`` pixels averaged, plus
    the chart error in the second case, and a light sloping across the chart in the third."""
    electrons = simulate_patches(truth, lamps, scene.chart) * WHITE_FILL * FULL_WELL_E
    std = np.sqrt(electrons + READ_NOISE_E**2) / np.sqrt(scene.pixels)
    out = electrons + std * rng.standard_normal(electrons.shape)
    if case != NOISE_CASES[0]:
        out *= 1.0 + CHART_ERROR * rng.standard_normal(out.shape)
    if case == NOISE_CASES[2]:
        slopes = rng.uniform(-UNEVEN_SLOPE, UNEVEN_SLOPE, (lamps.shape[0], 2))
        out *= (1.0 + slopes @ chart_coordinates().T)[:, :, None]
    return np.clip(out, 0.0, None)


def curve_errors(fit: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """RMSE of the curves normalised to a maximum of 1, and the mean angle (degrees) between
    fitted and true channel curves."""
    a, b = fit / fit.max(), truth / truth.max()
    cos = np.sum(a * b, axis=0) / (np.linalg.norm(a, axis=0) * np.linalg.norm(b, axis=0))
    angle = float(np.degrees(np.arccos(np.clip(cos, -1, 1))).mean())
    return float(np.sqrt(np.mean((a - b) ** 2))), angle


def downstream_delta_e(camera: np.ndarray, truth: np.ndarray, scene: Scene) -> dict[str, Any]:
    """ΔE00 per Munsell chip of reflectances estimated with ``camera`` from what the true camera
    sees under the rig's lights."""
    basis = default_basis(DEFAULT_GRID)
    true_resp = response_matrices(truth, scene.rig_lights)
    resp = response_matrices(camera, scene.rig_lights)
    resp *= true_resp.sum() / resp.sum()  # the wizard's white reference: white reads the same
    rgb = np.einsum("kcl,pl->pkc", true_resp, scene.munsell)
    estimate = estimate_reflectance(rgb, resp, basis)[1]
    return {
        name: delta_e00(estimate, scene.munsell, illuminant(name)) for name in DEFAULT_ILLUMINANTS
    }


def evaluate_camera(
    training: TrainingSet, name: str, scene: Scene, seeds: int, components: list[int]
) -> dict[str, Any]:
    """Every case (noise × lamps × prior components × seed) for one held-out camera."""
    truth = training.sensitivity(name)
    rest = training.without(name)
    priors = {k: build_prior(rest, k) for k in components}
    out: dict[str, Any] = {"floor": downstream_delta_e(truth, truth, scene), "cases": []}
    mean_curve = priors[components[0]].mean
    out["prior_mean"] = {
        "curve": curve_errors(mean_curve, truth),
        "delta_e": downstream_delta_e(mean_curve / mean_curve.max(), truth, scene),
    }
    for case in NOISE_CASES:
        for n_lamps in (1, 2):
            for k, prior in priors.items():
                for seed in range(seeds):
                    rng = np.random.default_rng([seed, n_lamps, NOISE_CASES.index(case)])
                    lamps = scene.lamps[:n_lamps]
                    fit = fit_camera(
                        noisy_patches(truth, lamps, scene, case, rng), lamps, scene.chart, prior
                    )
                    out["cases"].append(
                        {
                            "noise": case,
                            "lamps": n_lamps,
                            "components": k,
                            "seed": seed,
                            "curve": curve_errors(fit.sensitivity, truth),
                            "patch_error_percent": float(fit.patch_error_percent().mean()),
                            "delta_e": downstream_delta_e(fit.sensitivity, truth, scene),
                        }
                    )
    return out


def _de_cells(values: list[np.ndarray]) -> list[str]:
    v = np.concatenate(values)
    return [f"{v.mean():.2f} / {np.percentile(v, 90):.2f}"]


def tables(results: dict[str, dict[str, Any]], components: list[int]) -> list[ResultTable]:
    names = list(results)
    summary = ResultTable(
        f"Sensitivity from a chart, leave-one-camera-out ({len(names)} cameras): summary",
        [
            "method",
            "noise",
            "lamps",
            "RMSE mean / median / max",
            "angle ° mean",
            *(f"ΔE00 {n} mean / p90" for n in DEFAULT_ILLUMINANTS),
        ],
    )
    for label, key in (("true sensitivity (floor)", "floor"),):
        cells = [_de_cells([results[n][key][i] for n in names])[0] for i in DEFAULT_ILLUMINANTS]
        summary.add(label, "-", "-", "0", "0", *cells)
    rmse = np.array([results[n]["prior_mean"]["curve"][0] for n in names])
    angle = np.array([results[n]["prior_mean"]["curve"][1] for n in names])
    cells = [
        _de_cells([results[n]["prior_mean"]["delta_e"][i] for n in names])[0]
        for i in DEFAULT_ILLUMINANTS
    ]
    summary.add(
        "prior mean (no photo)",
        "-",
        "-",
        f"{rmse.mean():.4f} / {np.median(rmse):.4f} / {rmse.max():.4f}",
        f"{angle.mean():.2f}",
        *cells,
    )
    for k in components:
        for case in NOISE_CASES:
            for n_lamps in (1, 2):
                rows = [
                    c
                    for n in names
                    for c in results[n]["cases"]
                    if c["noise"] == case and c["lamps"] == n_lamps and c["components"] == k
                ]
                r = np.array([c["curve"][0] for c in rows])
                a = np.array([c["curve"][1] for c in rows])
                de = [_de_cells([c["delta_e"][i] for c in rows])[0] for i in DEFAULT_ILLUMINANTS]
                label = f"fit, {k} components" + (" (default)" if k == DEFAULT_COMPONENTS else "")
                summary.add(
                    label,
                    case,
                    n_lamps,
                    f"{r.mean():.4f} / {np.median(r):.4f} / {r.max():.4f}",
                    f"{a.mean():.2f}",
                    *de,
                )
    per_camera = ResultTable(
        f"Per held-out camera: fit with {DEFAULT_COMPONENTS} components, noise "
        f"'{NOISE_CASES[-1]}', mean over seeds",
        [
            "camera",
            "RMSE 1 / 2 lamps",
            "angle ° 1 / 2 lamps",
            "prior-mean RMSE",
            *(f"ΔE00 {n} mean: true / 1 / 2 lamps" for n in DEFAULT_ILLUMINANTS),
        ],
    )
    for n in names:
        by_lamps = {
            m: [
                c
                for c in results[n]["cases"]
                if c["noise"] == NOISE_CASES[-1]
                and c["lamps"] == m
                and c["components"] == DEFAULT_COMPONENTS
            ]
            for m in (1, 2)
        }
        if not by_lamps[1]:
            continue
        rm = {m: np.mean([c["curve"][0] for c in by_lamps[m]]) for m in (1, 2)}
        an = {m: np.mean([c["curve"][1] for c in by_lamps[m]]) for m in (1, 2)}
        de = []
        for i in DEFAULT_ILLUMINANTS:
            fitted = [np.mean([c["delta_e"][i].mean() for c in by_lamps[m]]) for m in (1, 2)]
            de.append(f"{results[n]['floor'][i].mean():.2f} / {fitted[0]:.2f} / {fitted[1]:.2f}")
        per_camera.add(
            n,
            f"{rm[1]:.4f} / {rm[2]:.4f}",
            f"{an[1]:.2f} / {an[2]:.2f}",
            f"{results[n]['prior_mean']['curve'][0]:.4f}",
            *de,
        )
    return [summary, per_camera]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="the shared data folder")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--pixels", type=int, default=400, help="pixels averaged per patch")
    ap.add_argument("--out", type=Path, default=Path("bench/results"))
    ap.add_argument("--quick", action="store_true", help="smoke size: 3 cameras, 1 seed")
    args = ap.parse_args()
    info = machine_info()
    training = read_camspec(data_file(args.data, CAMSPEC_TXT))
    scene = load_scene(args.data, args.pixels)
    names = training.names[:3] if args.quick else training.names
    seeds = 1 if args.quick else args.seeds
    components = [2, DEFAULT_COMPONENTS]
    with threadpool_limits(1):  # small matrices: threads only contend
        results = {n: evaluate_camera(training, n, scene, seeds, components) for n in names}
    payload = {
        "args": {k: str(v) for k, v in vars(args).items()},
        "lamps": LAMPS,
        "per_camera": {
            n: {
                "prior_mean_curve": r["prior_mean"]["curve"],
                "cases": [
                    {k: v for k, v in c.items() if k != "delta_e"}
                    | {
                        "delta_e_mean": {
                            i: float(c["delta_e"][i].mean()) for i in DEFAULT_ILLUMINANTS
                        }
                    }
                    for c in r["cases"]
                ],
            }
            for n, r in results.items()
        },
    }
    notes = [
        f"lamps: 1 = {LAMPS[0]}, 2 = + {LAMPS[1]} (../shared/data/{LAMPS_CSV})",
        f"sensor noise: white patch at {WHITE_FILL:.0%} of {FULL_WELL_E:g} e-, read noise "
        f"{READ_NOISE_E:g} e-, {args.pixels} pixels per patch; uneven light: a plane over the "
        f"chart, slopes uniform in ±{UNEVEN_SLOPE:g} per patch pitch along rows and columns; "
        f"{seeds} seed(s)",
        "ΔE00 over the 1269 Munsell chips under the default LED1..3 (8-component basis); "
        "'fit, 2 components' is Jiang et al.'s dimension in this fit",
    ]
    report(
        "camera_from_chart",
        args.out,
        tables(results, components),
        payload,
        info,
        make_console(),
        notes,
    )


if __name__ == "__main__":
    main()
