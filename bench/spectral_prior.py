"""The estimator's information floor under each spectral regulariser (issue 32).

Two lamps × RGB give six numbers for eight basis weights; what fills the rest is the spectral
regulariser (:mod:`calibration.prior`). This benchmark renders reflectances to exact camera RGB
(unit, known shading) with the measured camera and lamp pairs of the external scenes
(``bench.external``), adds relative noise, estimates them back with the 2-D estimator — bounded
to [0, 1] as every estimate is — under each regulariser and weight, and reports CIEDE2000 under
D65 and A and the spectral RMSE. Two reflectance sets: the 1269 Munsell chips of
``../shared/data`` (seen by neither the basis nor the prior: the set the prior's default weight
is read from) and the ColorChecker 24 the benchmark scenes are painted with (left out of the
prior; it is in the basis' training set).

    python -m bench.spectral_prior [--data ../shared/data] [--noise 0,0.01] [--seeds 3]
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from bench._common import DEFAULT_OUT, ResultTable, machine_info, make_console, report
from bench.external import SCENES
from bench.external_scene import DATA, camera_ssf, data_file, lamp_spd
from calibration import defaults
from calibration.basis import default_basis
from calibration.colour_difference import delta_e00, illuminant
from calibration.estimation import DEFAULT_SMOOTHNESS, estimate_reflectance, response_matrices
from calibration.grid import DEFAULT_GRID
from calibration.prior import TRAINING_STRENGTH, SpectralRegulariser, spectral_regulariser
from calibration.spectra import resample

MUNSELL_CSV = "reflectance/munsell_matt_1269_380_780_5nm.csv"
# relative weights tried for each regulariser (the estimator's `smoothness`): the default and
# the neighbours either side
WEIGHTS = (0.3, 1.0, 3.0)


def munsell(data: Path) -> np.ndarray:
    """The 1269 Munsell chips on the grid (P, N_λ), reflectance 0..1."""
    path = data_file(data, MUNSELL_CSV)
    with path.open() as handle:
        rows = list(csv.reader(handle))
    wl = np.array([float(w) for w in rows[0][1:]])
    values = np.array([[float(v) for v in row[1:]] for row in rows[1:]])
    return resample(wl, values.T, DEFAULT_GRID, source=str(path)).T


def score(
    truth: np.ndarray,
    resp: np.ndarray,
    reg: SpectralRegulariser,
    weight: float,
    noise: float,
    seeds: int,
) -> dict[str, float]:
    """Mean ΔE00 (D65, A), its 90th percentile under D65 and the RMSE over ``seeds`` noise
    draws (one without noise)."""
    basis = default_basis()
    d65, a = illuminant("D65"), illuminant("A")
    clean = np.einsum("kcl,pl->pkc", resp, truth)
    runs = []
    for seed in range(seeds if noise else 1):
        rng = np.random.default_rng(seed)
        rgb = clean * (1 + noise * rng.standard_normal(clean.shape))
        _, est = estimate_reflectance(
            rgb, resp, basis, DEFAULT_SMOOTHNESS * weight, regulariser=reg
        )
        de = delta_e00(est, truth, d65)
        runs.append(
            (
                de.mean(),
                np.percentile(de, 90),
                delta_e00(est, truth, a).mean(),
                np.sqrt(np.mean((est - truth) ** 2)),
            )
        )
    mean = np.mean(runs, axis=0)
    return {"de_d65": mean[0], "de_d65_p90": mean[1], "de_a": mean[2], "rmse": mean[3]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=DATA)
    p.add_argument("--noise", default="0,0.01", help="relative noise levels, comma-separated")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--out", type=Path, default=DEFAULT_OUT)
    a = p.parse_args(argv)
    noises = [float(n) for n in a.noise.split(",")]
    basis = default_basis()
    sets = {
        "Munsell 1269": munsell(a.data),
        "ColorChecker 24": defaults.colorchecker_reflectances()[1],
    }
    regs = {name: spectral_regulariser(name, basis) for name in ("smoothness", "training")}
    table = ResultTable(
        "2-D estimate, bounded, known shading: ΔE00 D65 mean / p90, ΔE00 A mean, RMSE "
        f"(training prior at {TRAINING_STRENGTH} of the smoothness's trace; weight × the "
        f"default relative weight {DEFAULT_SMOOTHNESS})",
        [
            "reflectances",
            "camera + lamps",
            "regulariser",
            "weight",
            *(f"noise {n:g}" for n in noises),
        ],
    )
    payload: dict[str, list[dict[str, object]]] = {"rows": []}
    for set_name, truth in sets.items():
        for spec in SCENES.values():
            lamps = [lamp_spd(a.data, name) for name in spec.lamps.values()]
            resp = response_matrices(camera_ssf(a.data, spec.camera), lamps)
            for reg_name, reg in regs.items():
                for weight in WEIGHTS:
                    cells = []
                    for noise in noises:
                        s = score(truth, resp, reg, weight, noise, a.seeds)
                        payload["rows"].append(
                            {"set": set_name, "scene": spec.name, "regulariser": reg_name,
                             "weight": weight, "noise": noise, **s}
                        )  # fmt: skip
                        cells.append(
                            f"{s['de_d65']:.2f} / {s['de_d65_p90']:.2f}, {s['de_a']:.2f}, "
                            f"{s['rmse']:.4f}"
                        )
                    table.add(set_name, f"{spec.camera}, {spec.name}", reg_name, weight, *cells)
    report("spectral_prior", a.out, [table], payload, machine_info(), make_console())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
