"""`rig batch` on a 2-worker local Dask cluster: three tiny sim sessions, one broken on purpose
(its calibration snapshot deleted): the broken one is reported with its one-line error, the two
others reconstructed; a second run skips those two; the summary CSV holds the figures."""

from __future__ import annotations

import csv
import shutil
import sys
from pathlib import Path

import pytest
from batch_sessions import FAST, copies

from core.errors import RigError
from core.install import install_command
from rig.batch.sessions import collect
from rig.batch.task import is_reconstructed
from rig.cli import main


def read_summary(path: Path) -> dict[str, dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return {Path(row["session"]).name: row for row in csv.DictReader(f)}


@pytest.mark.slow
def test_batch_isolates_a_broken_session_and_skips_done_ones(
    template: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    good1, good2, broken = copies(template, tmp_path, ["good1", "good2", "broken"])
    shutil.rmtree(broken / "calibration")
    listing = tmp_path / "sessions.txt"
    listing.write_text("# the collection\ngood2\nbroken\n")
    csv_path = tmp_path / "batch.csv"
    argv = ["batch", str(good1), "--list", str(listing), "--workers", "2"]
    argv += ["--config", str(FAST), "--summary", str(csv_path)]

    assert main(argv) == 1  # one session failed
    out, err = capfd.readouterr()
    rows = read_summary(csv_path)
    assert [rows[n]["status"] for n in ("good1", "good2", "broken")] == ["done", "done", "failed"]
    assert "calibration" in rows["broken"]["error"] and "\n" not in rows["broken"]["error"]
    assert f"failed: {broken}" in err
    for name in ("good1", "good2"):
        assert int(rows[name]["vertices"]) > 500
        assert int(rows[name]["observed_vertices"]) > 100
        assert float(rows[name]["cost_total"]) > 0
        assert len(rows[name]["light_offset_cm"].split()) == 3
        assert (tmp_path / name / "recon" / "mesh.ply").is_file()
        log = (tmp_path / name / "recon" / "log.txt").read_text()
        assert "optimise" in log and "INFO" in log  # each worker's chatter is in its log
    assert not (broken / "recon" / "mesh.ply").exists()
    assert "INFO" not in out + err  # quiet by default, workers included
    assert "done" in out and "failed" in out  # the table on stdout

    mtime = (good1 / "recon" / "mesh.ply").stat().st_mtime_ns
    assert main(argv) == 1
    rows = read_summary(csv_path)
    statuses = [rows[n]["status"] for n in ("good1", "good2", "broken")]
    assert statuses == ["skipped", "skipped", "failed"]
    assert rows["good1"]["vertices"] != ""  # figures read back from report.json
    assert (good1 / "recon" / "mesh.ply").stat().st_mtime_ns == mtime


def test_sessions_from_arguments_and_list(tmp_path: Path) -> None:
    listing = tmp_path / "l.txt"
    listing.write_text("a  # first\n\n/abs/b\na\n")
    got = collect([tmp_path / "a", Path("/abs/c")], listing)
    assert got == [tmp_path / "a", Path("/abs/c"), Path("/abs/b")]
    with pytest.raises(RigError, match="no session given"):
        collect([], None)
    with pytest.raises(RigError, match="cannot read --list"):
        collect([], tmp_path / "missing.txt")


def test_bad_arguments_are_one_line_errors(tmp_path: Path) -> None:
    assert main(["batch", str(tmp_path), "--workers", "0"]) == 2
    assert main(["batch", str(tmp_path), "--workers", "2", "--scheduler", "tcp://x:1"]) == 2
    assert main(["batch"]) == 2
    assert main(["batch", str(tmp_path), "--summary", str(tmp_path)]) == 2  # a folder: at once


@pytest.mark.slow
def test_a_session_with_an_unusable_frame_is_incomplete_not_done(
    template: Path, tmp_path: Path
) -> None:
    """As `rig reconstruct`'s exit 3: the run is not clean, the table says which frame."""
    (session,) = copies(template, tmp_path, ["partial"])
    raw = sorted((session / "raw").rglob("*.dng"))[3]
    raw.write_bytes(raw.read_bytes()[:4000])  # truncated after capture
    csv_path = tmp_path / "batch.csv"
    argv = ["batch", str(session), "--workers", "1", "--config", str(FAST)]
    assert main([*argv, "--summary", str(csv_path)]) == 3
    row = read_summary(csv_path)["partial"]
    assert row["status"] == "incomplete" and row["skipped_frames"] == "1"
    assert raw.name in row["error"]
    assert is_reconstructed(session)
    (session / "recon" / "outputs.json").unlink()  # as a kill mid-export leaves it
    assert not is_reconstructed(session)


def test_a_scheduler_with_multi_threaded_workers_is_refused() -> None:
    from distributed import LocalCluster

    from rig.batch.cluster import open_client

    with LocalCluster(
        n_workers=1, threads_per_worker=2, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        with pytest.raises(RigError, match="--nthreads 1"):
            with open_client(scheduler=cluster.scheduler_address):
                pass


def test_without_dask_batch_says_what_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # imports of it fail: not installed
    for name in ("rig.batch.run", "rig.batch.cluster"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    assert main(["batch", str(tmp_path)]) == 2
    err = capfd.readouterr().err
    assert install_command("batch") in err and len(err.strip().splitlines()) == 1
