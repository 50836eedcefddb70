"""Quiet by default: the real CLI on a tiny sim session prints no INFO line and no glog line
(caught at file-descriptor level with capfd, where COLMAP's C++ writes); both go to
recon/log.txt. -v brings our INFO lines back; -vv leaves native output on the terminal."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pycolmap
import pytest
from batch_sessions import FAST, copies

from reconstruct.run.logfile import captured_output
from rig.cli import main

GLOG = re.compile(r"^[IWEF]\d{8} \d\d:\d\d:\d\d", re.MULTILINE)  # glog's line prefix


@pytest.mark.slow
def test_reconstruct_is_quiet_by_default(
    template: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    (session,) = copies(template, tmp_path, ["s"])
    assert main(["reconstruct", str(session), "--config", str(FAST)]) == 0
    out, err = capfd.readouterr()
    assert "INFO" not in out + err and not GLOG.search(out + err)
    assert "optimise: light 0" in err and "optimise: joint 1" in err  # iteration bars
    assert "reconstruction" in err and str(session / "recon") in out  # results stay
    log = (session / "recon" / "log.txt").read_text()
    assert "INFO reconstruct: decode: running" in log
    assert "INFO reconstruct.optimise: joint 1    2" in log  # the iteration rows

    assert main(["-v", "reconstruct", str(session), "--config", str(FAST)]) == 0
    _, err = capfd.readouterr()
    assert "INFO" in err and "up to date, skipped" in err


def test_native_output_goes_to_the_log_unless_very_verbose(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    with captured_output(tmp_path / "recon") as log:
        pycolmap.logging.warning("a glog line from C++")
        print("python's stderr still reaches the terminal", file=sys.stderr)
    _, err = capfd.readouterr()
    assert "a glog line" not in err and "python's stderr" in err
    assert GLOG.search(log.read_text()) and "a glog line from C++" in log.read_text()
    with captured_output(tmp_path / "recon", native=True):
        pycolmap.logging.warning("shown with -vv")
    _, err = capfd.readouterr()
    assert "shown with -vv" in err
    with captured_output(tmp_path / "recon", terminal=False):
        pycolmap.logging.warning("worker native")
        print("worker python", file=sys.stderr)
    _, err = capfd.readouterr()
    assert "worker" not in err
    assert "worker native" in log.read_text() and "worker python" in log.read_text()
