"""`rig capture --resume` never deletes a frame: orphans are re-adopted when they verify or
moved to quarantine/, recorded frames are re-hashed, `rig session verify` reports leftovers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from fakes import fake_profile, fake_rig
from rich.console import Console
from simrig import PROFILE as SIM_PROFILE

from core.errors import RigError
from core.files import sha256_file
from core.manifest import MANIFEST_FILE, read_manifest, verify_frames
from rig.capture import run_capture
from rig.capture.resume import QUARANTINE_DIR, REASONS_FILE, quarantine
from rig.cli import main

QUIET = Console(quiet=True)
FRAMES = 16


def capture(out: Path, **kwargs):
    kwargs.setdefault("open_rig", fake_rig())
    return run_capture(fake_profile(), out, yes=True, console=QUIET, **kwargs)


def stopped_at(out: Path, fail_at: int) -> list[bytes]:
    """A session whose camera failed on shot ``fail_at``; its manifest lines."""
    with pytest.raises(RigError):
        capture(out, open_rig=fake_rig(fail_at=fail_at))
    return (out / MANIFEST_FILE).read_bytes().splitlines(keepends=True)


def hashes(folder: Path) -> dict[str, str]:
    return {p.name: sha256_file(p) for p in folder.iterdir() if p.is_file()}


def reasons(out: Path) -> dict[str, str]:
    lines = (out / QUARANTINE_DIR / REASONS_FILE).read_text().splitlines()
    return {json.loads(line)["was"]: json.loads(line)["reason"] for line in lines}


def assert_complete(out: Path) -> None:
    records = read_manifest(out)
    assert sorted(r.frame for r in records) == list(range(FRAMES))
    assert verify_frames(out, records) == []


def test_manifest_cut_mid_line_re_adopts_the_frame_and_captures_no_more(tmp_path: Path) -> None:
    out = tmp_path / "s"
    lines = stopped_at(out, 9)
    (out / MANIFEST_FILE).write_bytes(b"".join(lines[:-2]) + lines[-2][:40])  # two lines lost
    before = hashes(out / "raw")
    rig = fake_rig()
    capture(out, resume=True, open_rig=rig)
    assert_complete(out)
    assert rig.made["camera"].shots == FRAMES - 8  # the 2 cut frames were not shot again
    for name, digest in before.items():
        assert sha256_file(out / "raw" / name) == digest  # untouched, now owned again
    adopted = [r for r in read_manifest(out) if r.extra.get("readopted")]
    assert [r.frame for r in adopted] == [6, 7]
    assert adopted[0].exposure_s == 0.02 and adopted[0].iso == 100.0  # the session's settings


def test_manifest_removed_orphans_are_quarantined_when_unverifiable(tmp_path: Path) -> None:
    """NumPy frames carry no exposure; with no manifest left nothing says what it was."""
    out = tmp_path / "s"
    stopped_at(out, 5)
    before = hashes(out / "raw")
    (out / MANIFEST_FILE).unlink()
    capture(out, resume=True)
    assert_complete(out)
    kept = hashes(out / QUARANTINE_DIR)
    assert set(before.values()) <= set(kept.values())  # every original kept, byte for byte
    assert all("exposure" in why for why in reasons(out).values())
    assert main(["session", "verify", str(out)]) == 1  # quarantined frames: not verified


def test_sim_manifest_removed_every_frame_is_re_adopted(tmp_path: Path) -> None:
    pytest.importorskip("drivers.sim")
    out = tmp_path / "s"
    run_capture(SIM_PROFILE, out, yes=True, console=QUIET)
    original = {
        json.loads(line)["frame"]: json.loads(line)
        for line in (out / MANIFEST_FILE).read_text().splitlines()
    }
    (out / MANIFEST_FILE).unlink()
    shots: list[int] = []
    run_capture(None, out, yes=True, resume=True, console=QUIET, on_frame=lambda r: shots.append(1))
    assert shots == []  # nothing captured again: the DNGs decode and carry exposure and ISO
    records = read_manifest(out)
    assert verify_frames(out, records) == [] and len(records) == len(original)
    for record in records:
        old = original[record.frame]
        assert (record.path, record.sha256, record.view) == (
            old["path"],
            old["sha256"],
            old["view"],
        )
        assert (record.exposure_s, record.iso) == (old["exposure_s"], old["iso"])
    assert main(["session", "verify", str(out)]) == 0


def test_manifest_with_a_binary_line_is_refused_and_nothing_moves(tmp_path: Path) -> None:
    out = tmp_path / "s"
    lines = stopped_at(out, 9)
    (out / MANIFEST_FILE).write_bytes(
        b"".join(lines[:3]) + b"\xff\xfe\x00junk\n" + b"".join(lines[3:])
    )
    before = hashes(out / "raw")
    with pytest.raises(RigError, match=r"manifest.jsonl line 4 is not text"):
        capture(out, resume=True)
    assert hashes(out / "raw") == before
    assert main(["session", "verify", str(out)]) == 2


def test_a_corrupt_orphan_is_quarantined_and_captured_again(tmp_path: Path) -> None:
    out = tmp_path / "s"
    lines = stopped_at(out, 9)
    (out / MANIFEST_FILE).write_bytes(b"".join(lines[:-1]))
    lost = json.loads(lines[-1])["path"]
    torn = (out / lost).read_bytes()[:90]
    (out / lost).write_bytes(torn)
    capture(out, resume=True)
    assert_complete(out)
    assert "does not decode" in reasons(out)[lost]
    assert (out / QUARANTINE_DIR / Path(lost).name).read_bytes() == torn


def test_a_recorded_frame_whose_hash_differs_is_quarantined_never_deleted(tmp_path: Path) -> None:
    out = tmp_path / "s"
    lines = stopped_at(out, 9)
    victim = json.loads(lines[2])
    changed = np.zeros((16, 16), np.uint16)
    np.save(out / victim["path"], changed)  # decodes fine, but is not what was recorded
    data = (out / victim["path"]).read_bytes()
    assert main(["session", "verify", str(out)]) == 1
    capture(out, resume=True)
    assert_complete(out)
    assert reasons(out)[victim["path"]] == "its sha256 differs from the manifest"
    assert (out / QUARANTINE_DIR / Path(victim["path"]).name).read_bytes() == data
    assert list((out / QUARANTINE_DIR).glob("manifest-*.jsonl"))  # the old manifest is kept
    assert main(["session", "verify", str(out)]) == 1  # until the person clears quarantine/


def test_a_stray_file_and_a_cut_download_are_quarantined(tmp_path: Path) -> None:
    out = tmp_path / "s"
    stopped_at(out, 5)
    (out / "raw" / "holiday.jpg").write_bytes(b"not a frame")
    (out / "raw" / ".incoming" / "f00004.npy").write_bytes(b"half")
    assert main(["session", "verify", str(out)]) == 1  # orphans are reported
    capture(out, resume=True)
    assert_complete(out)
    why = reasons(out)
    assert why["raw/holiday.jpg"] == "not named after a frame of the plan"
    assert why["raw/.incoming/f00004.npy"] == "an unfinished download"
    assert (out / QUARANTINE_DIR / "holiday.jpg").read_bytes() == b"not a frame"


def test_a_missing_recorded_frame_stops_the_resume(tmp_path: Path) -> None:
    out = tmp_path / "s"
    lines = stopped_at(out, 9)
    (out / json.loads(lines[0])["path"]).unlink()
    with pytest.raises(RigError, match="missing from raw/"):
        capture(out, resume=True)


def test_a_re_hash_killed_before_its_manifest_rewrite_resumes(tmp_path: Path) -> None:
    """The bad frame's file was moved to quarantine/ and logged, the manifest not yet
    rewritten: the next resume drops that line and captures the frame again."""
    out = tmp_path / "s"
    lines = stopped_at(out, 9)
    victim = json.loads(lines[2])
    np.save(out / victim["path"], np.zeros((16, 16), np.uint16))
    quarantine(out, out / victim["path"], "its sha256 differs from the manifest", lambda _: None)
    assert (out / MANIFEST_FILE).read_bytes() == b"".join(lines)  # the kill came here
    capture(out, resume=True)
    assert_complete(out)


@pytest.mark.parametrize("folder", ["raw", "raw/.incoming", "quarantine"])
def test_a_session_folder_linked_elsewhere_is_refused_and_nothing_moves(
    tmp_path: Path, folder: str
) -> None:
    out = tmp_path / "s"
    stopped_at(out, 5)
    (out / "raw" / "stray.txt").write_bytes(b"someone's file")
    elsewhere = tmp_path / "documents"
    (out / folder).mkdir(parents=True, exist_ok=True)
    (out / folder).rename(elsewhere)
    (out / folder).symlink_to(elsewhere, target_is_directory=True)
    before = {p.relative_to(tmp_path): p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    with pytest.raises(RigError, match=f"{folder} is a link out of the session"):
        capture(out, resume=True)
    after = {p.relative_to(tmp_path): p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    assert after == before


def test_resume_with_a_profile_never_deletes_frames_of_a_session_without_session_yaml(
    tmp_path: Path,
) -> None:
    out = tmp_path / "s"
    stopped_at(out, 5)
    (out / "session.yaml").unlink()
    (out / MANIFEST_FILE).write_bytes(b"")  # manifest lost too
    before = hashes(out / "raw")
    with pytest.raises(RigError, match="nothing was deleted"):
        capture(out, resume=True)
    assert hashes(out / "raw") == before


def test_resume_with_a_profile_starts_afresh_after_a_kill_before_session_yaml(
    tmp_path: Path,
) -> None:
    out = tmp_path / "s"
    (out / "raw" / ".incoming").mkdir(parents=True)
    (out / MANIFEST_FILE).write_bytes(b"")
    capture(out, resume=True)
    assert_complete(out)
