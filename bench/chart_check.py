"""`rig check-chart` on flat ColorCheckers rendered by Mitsuba 3: how far the ΔE00 it reports
per patch is from what the session's calibration gives with the shading known.

Per scene (measured camera and lamps, the chart seen from a few views, one at least upside
down) the chart session of :mod:`bench.chart_session` goes through the command itself; its
``chart_check.json`` is scored against (a) the same patches divided by their true shading (the
estimate the check would give if it knew the shading: what its normalisation costs) and (b)
the noise-free information floor (``A_k ρ`` estimated back: what the calibration and estimator
give at best; the scene's noise adds to the difference).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from bench._common import ResultTable, machine_info, make_console, report
from bench.chart_session import CHART_SPEC, ChartSize, build_chart_session
from bench.external_scene import DATA, SceneSpec

SCENES = {
    "d700-sunwayfoto": CHART_SPEC,
    "600d-elgato": SceneSpec(
        "chart",
        "",
        {"L1": "elgato:at.2900K.dimmed.to.100pc", "L2": "elgato:at.7000K.dimmed.to.100pc"},
        "Canon 600D",
        (1.0,),
        (55.0,),
        seed=1,
    ),
    "nex5n-toshiba": SceneSpec(
        "chart",
        "",
        {"L1": "Toshiba.LED.12W.2700K", "L2": "V.light.LED.2W.6000K"},
        "SONY NEX-5N",
        (1.0,),
        (80.0,),
        seed=2,
    ),
}
LIGHTS = ("D65", "A")


def score(session: Path, result: dict[str, Any]) -> dict[str, Any]:
    """ΔE00 per patch as reported, with the true shading, and at the floor, per illuminant."""
    from calibration.basis import default_basis
    from calibration.colour_difference import delta_e00, illuminant
    from calibration.defaults import colorchecker_reflectances
    from calibration.estimation import estimate_reflectance
    from core.session import Session
    from reconstruct.run.pipeline import session_responses

    responses = session_responses(Session.open(session))
    basis = default_basis()
    truth = colorchecker_reflectances()[1]
    predicted = np.einsum("kcl,pl->pkc", responses, truth)
    names = result["illuminations"]
    known = []
    for view in result["views"]:
        y = np.stack([np.array(view["rgb"][n]) for n in names], axis=1)
        shading = np.median((y / predicted).reshape(len(truth), -1), axis=1)
        known.append(estimate_reflectance(y / shading[:, None, None], responses, basis)[1])
    floor = estimate_reflectance(predicted, responses, basis)[1]
    out: dict[str, Any] = {"views": [v["view"] for v in result["views"]]}
    for light in LIGHTS:
        lit = illuminant(light)
        out[light] = {
            "reported": np.array([row[f"delta_e00_{light}"] for row in result["patches"]]),
            "known_shading": delta_e00(np.median(known, axis=0), truth, lit),
            "floor": delta_e00(floor, truth, lit),
        }
    return out


def run_scene(name: str, spec: SceneSpec, size: ChartSize, out: Path, data: Path) -> dict[str, Any]:
    from rig.cli import main

    session = build_chart_session(out / name, data, spec, size)
    if main(["check-chart", str(session)]) != 0:
        raise RuntimeError(f"rig check-chart failed on {session}")
    result = json.loads((session / "recon" / "chart_check" / "chart_check.json").read_text())
    return score(session, result)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one scene, two views")
    ap.add_argument("--views", type=int, default=4)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--out", type=Path, default=Path("bench/results"))
    ap.add_argument("--data", type=Path, default=DATA, help="the shared data folder")
    args = ap.parse_args()
    scenes = dict(list(SCENES.items())[:1]) if args.quick else SCENES
    size = ChartSize(views=2 if args.quick else args.views, spp=args.spp)
    work = args.out / "chart_check_work"
    table = ResultTable(
        "rig check-chart on rendered charts: ΔE00 per patch (mean / max)",
        ["scene", "views found", *(f"{n} {w}" for n in LIGHTS
                                   for w in ("reported", "|reported − known shading|",
                                             "|reported − floor|"))],
    )  # fmt: skip
    payload: dict[str, Any] = {}
    for name, spec in scenes.items():
        s = run_scene(name, spec, size, work, args.data)
        payload[name] = s
        cells: list[object] = [name, f"{len(s['views'])} of {size.views}"]
        for light in LIGHTS:
            rep, known, floor = (s[light][k] for k in ("reported", "known_shading", "floor"))
            for values in (rep, np.abs(rep - known), np.abs(rep - floor)):
                cells.append(f"{values.mean():.2f} / {values.max():.2f}")
        table.add(*cells)
    notes = [f"{size.width}x{size.height}, {size.spp} spp, chart card 148 mm at 0.5 m"]
    report("chart_check", args.out, [table], {"scenes": payload}, machine_info(),
           make_console(), notes)  # fmt: skip


if __name__ == "__main__":
    main()
