"""Ambient subtraction and per-vertex uncertainty on a synthetic image scene with known truth.

Three solves of the same bumpy sphere (images, sensor-like noise, a perturbed start mesh): no room
light; a uniform illuminant-A room light at ``--level`` of the bulb left in the frames; the same
with each view's ambient frame subtracted (:func:`reconstruct.frames.ambient.subtract_ambient`, the
pipeline's code). Reports the spectral RMSE over observed vertices and, for the solves with a dark
or subtracted room, how often the truth lies inside the ±2σ band (per vertex and band, and per
vertex over all bands), the calibration curve and the Spearman rank correlation between the
predicted std and the actual error.

    python -m bench.ambient_uncertainty --out bench/results/ambient_uncertainty
    python -m bench.ambient_uncertainty --perturb 0   # start at the true shape

``--perturb`` sets the start mesh's displacement (1 mm RMS along the normals by default; from
that start the solve settles with part of it and the light off, see docs/usage-reconstruct.md).

Writes ``OUT/results.json`` (all numbers) and ``OUT/calibration.png``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from scipy.stats import norm, spearmanr

from reconstruct.frames.ambient import subtract_ambient
from reconstruct.optimise.problem import Frames
from reconstruct.optimise.settings import OptimiseSettings
from reconstruct.optimise.steps import OptimiseResult, optimise
from reconstruct.optimise.synthetic import SyntheticScene, make_scene, perturb


def subtracted_frames(scene: SyntheticScene) -> Frames:
    """The scene's lit frames with each view's ambient frame subtracted (exposures equal)."""
    f = scene.frames
    assert f.images is not None and f.valid is not None and scene.ambient_images is not None
    images, valid, weight = [], [], []
    for k in range(f.count):
        amb = scene.ambient_images[f.view[k]]
        out = subtract_ambient(
            f.images[k], f.valid[k], amb, np.ones(amb.shape[:2], bool), 1.0, f"view {f.view[k]}"
        )
        images.append(out.image)
        valid.append(out.valid)
        weight.append(out.weight)
    return Frames(f.view, f.illumination, np.stack(images), np.stack(valid), np.array(weight))


def solve(scene: SyntheticScene, frames: Frames, start: np.ndarray) -> OptimiseResult:
    inp = scene.input(start, images=True)
    inp.frames = frames
    return optimise(inp, OptimiseSettings(outer_iterations=2, joint_iterations=10))


def calibration(err: np.ndarray, std: np.ndarray) -> dict[str, Any]:
    """Coverage of |error| ≤ z σ for nominal Gaussian levels, and the ±2σ numbers."""
    z = np.abs(err) / std
    levels = np.array([0.5, 0.68, 0.8, 0.9, 0.95, 0.99])
    return {
        "nominal": levels.tolist(),
        "empirical": [float(np.mean(z <= norm.ppf(0.5 + q / 2))) for q in levels],
        "inside_2sigma_per_band": float(np.mean(z <= 2.0)),
        "inside_2sigma_all_bands": float(np.mean(np.all(z <= 2.0, axis=1))),
        "inside_2sigma_by_wavelength": np.mean(z <= 2.0, axis=0).round(4).tolist(),
        "median_z": float(np.median(z)),
        "rms_z": float(np.sqrt(np.mean(z**2))),
    }


def evaluate(scene: SyntheticScene, res: OptimiseResult) -> dict[str, Any]:
    seen = res.observed
    err = res.reflectance[seen] - scene.reflectance[seen]
    out: dict[str, Any] = {
        "rmse": float(np.sqrt(np.mean(err**2))),
        "observed": int(seen.sum()),
        "light_offset_error_m": float(np.linalg.norm(res.light[0] - scene.light_offset)),
    }
    unc = res.uncertainty
    if unc is not None:
        out["uncertainty"] = unc.summary()
        rms = np.sqrt(np.mean(err**2, axis=1))
        for key, full in (("", unc.reflectance_std), ("_gn", unc.reflectance_std_gn)):
            if full is None:
                continue
            std = full[seen]
            out["calibration" + key] = calibration(err, std)
            rho = spearmanr(np.mean(std, axis=1), rms).statistic
            out["spearman_std_vs_error" + key] = float(rho)
        pos = unc.position_std_m[seen]
        ok = np.isfinite(pos)
        normals = scene.vertices[seen] / np.linalg.norm(scene.vertices[seen], axis=1)[:, None]
        d_pos = np.einsum("ij,ij->i", res.vertices[seen] - scene.vertices[seen], normals)
        if ok.any():
            out["position_inside_2sigma"] = float(np.mean(np.abs(d_pos[ok]) <= 2 * pos[ok]))
            out["position_spearman"] = float(spearmanr(pos[ok], np.abs(d_pos[ok])).statistic)
    return out


def plot(path: Path, results: dict[str, dict[str, Any]]) -> None:
    fig, ax = plt.subplots(figsize=(5, 5))
    ax.plot([0, 1], [0, 1], color="0.6", lw=0.8, ls="--", label="ideal")
    for name, r in results.items():
        for key, how in (("calibration", "training prior"), ("calibration_gn", "plain GN")):
            if key in r:
                c = r[key]
                ax.plot(c["nominal"], c["empirical"], marker="o", label=f"{name} ({how})")
    ax.set_xlabel("nominal Gaussian coverage")
    ax.set_ylabel("fraction of (vertex, band) truths inside")
    ax.set_title("Reflectance uncertainty calibration", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subdivisions", type=int, default=4)
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--level", type=float, default=0.1)
    ap.add_argument("--noise", type=float, default=0.003)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--perturb",
        type=float,
        default=0.001,
        help="start mesh: RMS displacement along the normals in m (0: the true shape)",
    )
    ap.add_argument("--out", type=Path, default=Path("bench/results/ambient_uncertainty"))
    ap.add_argument("--quick", action="store_true", help="smoke size: 162 vertices, 6 views")
    args = ap.parse_args()
    if args.quick:
        args.subdivisions, args.views = 2, 6
    common = dict(n_views=args.views, image_size=(320, 240), noise=args.noise, seed=args.seed)
    dark = make_scene(args.subdivisions, **common)  # type: ignore[arg-type]
    room = make_scene(args.subdivisions, ambient=args.level, **common)  # type: ignore[arg-type]
    start = perturb(dark, args.perturb)
    results = {
        "no ambient": evaluate(dark, solve(dark, dark.frames, start)),
        f"ambient {args.level:g}, not subtracted": evaluate(room, solve(room, room.frames, start)),
        f"ambient {args.level:g}, subtracted": evaluate(
            room, solve(room, subtracted_frames(room), start)
        ),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    plot(args.out / "calibration.png", results)
    (args.out / "results.json").write_text(
        json.dumps({"args": vars(args) | {"out": str(args.out)}, "results": results}, indent=2)
    )
    for name, r in results.items():
        print(name, json.dumps(r, indent=1))


if __name__ == "__main__":
    main()
