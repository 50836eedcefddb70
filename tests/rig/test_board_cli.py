"""`rig board`: printable sheets at their physical size and the profile snippet."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from reconstruct.poses.board import BoardSpec, detect_board
from rig.cli import main

MM_PER_INCH = 25.4


def test_png_has_its_dpi_and_prints_to_scale(tmp_path: Path) -> None:
    out = tmp_path / "x.png"
    assert main(["board", "--out", str(out), "--dpi", "150"]) == 0
    spec = BoardSpec.from_yaml(tmp_path / "x.yaml")
    assert spec.squares == (10, 7) and spec.paper == "A4"
    with Image.open(out) as png:
        dpi = png.info["dpi"]
        size = png.size
        grey = np.asarray(png.convert("L"))
    assert dpi == pytest.approx((150, 150), abs=0.05)  # pHYs stores whole px per metre
    assert size[0] == pytest.approx(297 / MM_PER_INCH * 150, abs=1)  # A4 landscape
    assert size[1] == pytest.approx(210 / MM_PER_INCH * 150, abs=1)
    det = detect_board(grey, spec)
    assert det.n_corners == spec.n_corners
    # Corner spacing on the sheet = the square length at the file's DPI.
    step = np.diff(det.corners[: spec.squares[0] - 1, 0]).mean()
    assert step == pytest.approx(spec.square_length_m * 1000 / MM_PER_INCH * 150, rel=0.005)


def test_pdf_page_is_the_sheet(tmp_path: Path) -> None:
    out = tmp_path / "x.pdf"
    assert main(["board", "--out", str(out), "--size", "A3", "--squares", "12x8"]) == 0
    data = out.read_bytes()
    assert data.startswith(b"%PDF")
    box = re.search(rb"/MediaBox \[ *0 0 ([\d.]+) ([\d.]+) *\]", data)
    assert box is not None
    width_mm, height_mm = (float(v) / 72 * MM_PER_INCH for v in box.groups())
    assert (width_mm, height_mm) == pytest.approx((420.0, 297.0), abs=0.01)
    spec = BoardSpec.from_yaml(tmp_path / "x.yaml")
    assert spec.squares == (12, 8) and spec.paper == "A3"
    assert spec.size_m[0] <= 0.420 - 0.024 + 1e-9 and spec.size_m[1] <= 0.297 - 0.024 + 1e-9


def test_measured_square_is_recorded(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "board.pdf"
    snippet = tmp_path / "profile-board.yaml"
    assert main(["board", "--out", str(out), "--snippet", str(snippet), "--square-mm", "25"]) == 0
    assert main(["board", "--snippet", str(snippet), "--measured-square-mm", "24.75"]) == 0
    assert "print scale 0.9900" in capsys.readouterr().out
    spec = BoardSpec.from_yaml(snippet)
    assert spec.square_length_m == pytest.approx(0.025)
    assert spec.square_m == pytest.approx(0.02475)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--out", "x.txt"], "name the output .pdf or .png"),
        ([], "nothing to do"),
        (["--out", "x.pdf", "--square-mm", "60"], "do not fit on A4"),
        (["--snippet", "missing.yaml", "--measured-square-mm", "25"], "does not exist"),
    ],
)
def test_errors_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    argv = [str(tmp_path / a) if a.endswith((".txt", ".pdf", ".yaml")) else a for a in argv]
    assert main(["board", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
