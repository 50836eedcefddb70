"""`rig calibrate camera --from-chart` on RAW photos of a ColorChecker rendered by Mitsuba 3 (a
Nikon D700 under two measured LED lamps, the light falling off across the card), read by the chart
reader: the held-out camera comes back close to its measurement."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bench.external_session import CAMERA_NAME
from calibration.store import CalibrationStore
from rig.cli import main

pytest.importorskip("reconstruct.chart")
chart_session = pytest.importorskip("bench.chart_session")


@pytest.mark.slow
def test_a_rendered_chart_gives_back_the_held_out_camera(
    tmp_path: Path, shared_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = chart_session.CHART_SPEC
    session = chart_session.build_chart_session(tmp_path, shared_data)
    camspec = (shared_data / "camera_ssf" / "camspec_database_27.txt").read_text().splitlines()
    at = camspec.index(spec.camera)
    prior = tmp_path / "prior.txt"
    prior.write_text("\n".join(camspec[:at] + camspec[at + 4 :]) + "\n")
    raws = sorted((session / "raw").glob("v000_*.dng"))
    lamps = list(spec.lamps)  # the session store's light names, in the frames' order
    assert [r.stem.rsplit("_", 1)[1] for r in raws] == lamps
    store_dir = tmp_path / "store"
    args = ["calibrate", "camera", "--store", str(store_dir), "--from-chart", *map(str, raws)]
    plot = tmp_path / "fit.png"
    assert (
        main(
            [
                *args,
                "--lamp",
                *lamps,
                "--name",
                "fitted",
                "--prior",
                str(prior),
                "--plot",
                str(plot),
            ]
        )
        == 0
    )
    assert "the light varies by" in capsys.readouterr().out
    store = CalibrationStore(store_dir)
    truth = store.camera(CAMERA_NAME)
    truth = truth / truth.max()
    # measured 0.025 (the prior's mean alone: 0.043); without the light's plane: 0.35
    assert np.sqrt(np.mean((store.camera("fitted") - truth) ** 2)) < 0.035
    assert store.entry("fitted").provenance["fit"]["light_unevenness_percent"] > 20
    assert plot.is_file()
