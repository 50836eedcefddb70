"""The bad-input table of issue 34, the file-system side: full disks (ENOSPC), read-only and
foreign-owned folders (EROFS, EACCES), a file where a folder should be, links out of a
session, files written outside it, and nonsense in the data (spectra, frame metadata, truth).

Each row runs the real CLI (`rig.cli.main`, in-process; a few in their own process) and expects
a non-zero exit, one line matching ``expect`` (`rig session verify` reports with exit 1 and
its own lines instead), no internal error or traceback — and that no byte under the test's
folder changed but the paths the row allows (``may_change``, globs relative to it): nothing
half-written is left behind. Failures are simulated in-process (tests/rig/fsfaults.py), so the
rows run the same as root, as the CI does, as as a user.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from fnmatch import fnmatch
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml
from fsfaults import Faults
from simrig import PROFILE, capture_small_session
from test_bad_inputs import run_cli, write

from calibration.store import CalibrationStore

pytest.importorskip("drivers.sim")
ROOT = Path(__file__).parents[2]
W = np.arange(400.0, 701.0, 10.0)
NO_SPACE = r"no space left on the disk holding "
READ_ONLY = r"(?i)read-only file system"  # the lock file's own line says it so
DENIED = r"(?i)permission denied"
LINK_OUT = r"is a link out of the session"


@dataclass(frozen=True)
class Case:
    id: str
    kind: str  # data loss, crash, nonsense or escape: what issue 34 found of this kind
    make: Callable[[Path, Faults], list[str]]  # builds the inputs under tmp, returns argv
    expect: str  # a regular expression the error line must match
    may_change: tuple[str, ...] = ()  # globs (relative to tmp) of what the command may change
    code: int = 2
    check: Callable[[Path], None] | None = None  # more to assert afterwards
    process: bool = False  # run `rig` in its own process (a library's state at start-up)


@pytest.fixture(scope="module")
def base_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return capture_small_session(tmp_path_factory.mktemp("base") / "s")


BASE: list[Path] = []  # the module's session, for the rows' make functions


def session(tmp: Path) -> Path:
    """A copy of the module's captured session (2 views, 8 frames) at ``tmp/s``."""
    target = tmp / "s"
    shutil.copytree(BASE[0], target, symlinks=True)
    return target


def small_profile(tmp: Path) -> Path:
    profile = yaml.safe_load(PROFILE.read_text())
    profile["plan"]["views"] = 2
    return write(tmp / "p.yaml", yaml.safe_dump(profile))


def lines(s: Path) -> list[dict[str, object]]:
    return [json.loads(x) for x in (s / "manifest.jsonl").read_text().splitlines()]


def set_lines(s: Path, records: list[dict[str, object]]) -> None:
    (s / "manifest.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))


def unfinished(tmp: Path) -> Path:
    """The session with its last two frames not captured yet (their lines and files gone)."""
    s = session(tmp)
    records = lines(s)
    for record in records[-2:]:
        (s / str(record["path"])).unlink()
    set_lines(s, records[:-2])
    return s


def store(tmp: Path, name: str = "st") -> Path:
    root = tmp / name
    cal = CalibrationStore(root)
    cal.add_light("LED1", W, np.exp(-(((W - 550) / 60) ** 2)), {"source": "test"})
    cal.add_camera("cam", W, np.ones((W.size, 3)), {"source": "test"})
    return root


def status_is_failed(tmp: Path) -> None:
    data = json.loads((tmp / "s" / "recon" / "status.json").read_text())
    assert data["status"] == "failed" and "no space" in data["error"], data


def left_resumable(tmp: Path) -> None:
    """What a failed capture left is a session that resumes to completion."""
    from rig.cli import main

    assert main(["capture", "--resume", str(tmp / "new"), "--yes"]) == 0
    assert main(["session", "verify", str(tmp / "new")]) == 0


# -- the commands --------------------------------------------------------------------------------
def capture_new(
    fail: Callable[[Path, Faults], None], out: str = "new"
) -> Callable[[Path, Faults], list[str]]:
    def make(tmp: Path, faults: Faults) -> list[str]:
        profile = small_profile(tmp)
        fail(tmp, faults)
        return ["capture", "--yes", "--profile", str(profile), "--out", str(tmp / out)]

    return make


def resume(fail: Callable[[Path, Faults], None]) -> Callable[[Path, Faults], list[str]]:
    def make(tmp: Path, faults: Faults) -> list[str]:
        s = unfinished(tmp)
        fail(s, faults)
        return ["capture", "--yes", "--resume", str(s)]

    return make


def on_session(command: str, fail: Callable[[Path, Faults], None]) -> Callable[
    [Path, Faults], list[str]
]:
    """``rig reconstruct S`` / ``session verify S`` / ``capture --resume S`` after ``fail``."""
    argv = {
        "reconstruct": ["reconstruct"],
        "verify": ["session", "verify"],
        "resume": ["capture", "--yes", "--resume"],
        "info": ["session", "info"],
    }[command]

    def make(tmp: Path, faults: Faults) -> list[str]:
        s = session(tmp)
        fail(s, faults)
        return [*argv, str(s)]

    return make


def board(fail: Callable[[Path, Faults], None], *args: str) -> Callable[[Path, Faults], list[str]]:
    def make(tmp: Path, faults: Faults) -> list[str]:
        (tmp / "out").mkdir()
        write(tmp / "out" / "old.yaml", "board: {}\n")
        fail(tmp / "out", faults)
        return ["board", *(a.replace("OUT", str(tmp / "out")) for a in args)]

    return make


def calibrate(
    fail: Callable[[Path, Faults], None], *args: str, with_store: bool = True
) -> Callable[[Path, Faults], list[str]]:
    """``rig calibrate ARGS`` (TMP, ST replaced) with a store at tmp/st unless not wanted."""

    def make(tmp: Path, faults: Faults) -> list[str]:
        if with_store:
            store(tmp)
        write(tmp / "spd.csv", "wavelength_nm,power\n" + "".join(f"{w:g},1\n" for w in W))
        write(tmp / "chips.csv", "wavelength_nm,a,b,c\n" + "".join(
            f"{w:g},0.2,0.5,0.8\n" for w in W))  # fmt: skip
        fail(tmp, faults)
        return ["calibrate", *(a.replace("ST", str(tmp / "st")).replace("TMP", str(tmp))
                               for a in args)]

    return make


def nothing(path: Path, faults: Faults) -> None:
    """No failure injected: the input itself is what is wrong."""


# -- failures ------------------------------------------------------------------------------------
def full(*globs: str, budget: int = 0) -> Callable[[Path, Faults], None]:
    """ENOSPC writing anything under the globs (relative to the given folder; "" = itself)."""
    return lambda base, faults: faults.full(
        *(f"{base}/{g}" if g else str(base) for g in globs), budget=budget
    )


def read_only(*globs: str) -> Callable[[Path, Faults], None]:
    return lambda base, faults: faults.read_only(
        *(f"{base}/{g}" if g else str(base) for g in globs)
    )


def no_permission(sub: str = "") -> Callable[[Path, Faults], None]:
    return lambda base, faults: faults.no_permission(base / sub if sub else base)


def edit_manifest(change: Callable[[list[dict[str, object]]], object]) -> Callable[
    [Path, Faults], None
]:
    def fail(s: Path, faults: Faults) -> None:
        records = lines(s)
        change(records)
        set_lines(s, records)

    return fail


def duplicate_line(records: list[dict[str, object]]) -> None:
    records.append(dict(records[0]))


def shared_file(records: list[dict[str, object]]) -> None:
    records[1]["path"], records[1]["sha256"] = records[0]["path"], records[0]["sha256"]


def key(name: str, value: object, line: int = 0) -> Callable[[list[dict[str, object]]], None]:
    return lambda records: records[line].update({name: value})


def frame_link_out(s: Path, faults: Faults) -> None:
    """Frame 1's file replaced by a link to an identical file outside the session."""
    frame = s / str(lines(s)[1]["path"])
    outside = s.parent / "outside.dng"
    shutil.copyfile(frame, outside)
    frame.unlink()
    frame.symlink_to(outside)


def manifest_link_out(s: Path, faults: Faults) -> None:
    outside = s.parent / "manifest.jsonl"
    shutil.copyfile(s / "manifest.jsonl", outside)
    (s / "manifest.jsonl").unlink()
    (s / "manifest.jsonl").symlink_to(outside)


def manifest_a_folder(s: Path, faults: Faults) -> None:
    (s / "manifest.jsonl").unlink()
    (s / "manifest.jsonl").mkdir()


def a_file(name: str) -> Callable[[Path, Faults], None]:
    def fail(s: Path, faults: Faults) -> None:
        write(s / name, "x")

    return fail


DATA_LOSS = [
    # full disks: one line naming the file, nothing half-written
    Case("capture-full-at-start", "data loss", capture_new(full("new", "new/*")),
         NO_SPACE + r".*new"),
    Case("capture-full-after-frames", "data loss", capture_new(full("new/raw/*", budget=1_500)),
         NO_SPACE + r".*new/raw/", ("new", "new/*"), check=left_resumable),
    Case("capture-full-manifest", "data loss",
         capture_new(full("new/manifest.jsonl", budget=2_000)),
         NO_SPACE + r".*new/manifest\.jsonl", ("new", "new/*"), check=left_resumable),
    Case("capture-full-calibration", "data loss", capture_new(full("new/calibration/*")),
         NO_SPACE + r".*new/calibration/"),
    Case("capture-full-ground-truth", "data loss", capture_new(full("new/ground_truth/*")),
         NO_SPACE + r".*new/ground_truth/"),
    Case("capture-full-session-yaml", "data loss", capture_new(full("new/.session.tmp.yaml")),
         NO_SPACE + r".*new/session\.yaml"),
    Case("resume-full-raw", "data loss", resume(full("raw/*")), NO_SPACE + r".*s/raw/",
         ("s/raw/.incoming", "s/session.yaml")),
    Case("resume-full-manifest", "data loss", resume(full("manifest.jsonl")),
         NO_SPACE + r".*s/manifest\.jsonl", ("s/raw/*", "s/session.yaml")),
    Case("resume-full-session-lock", "data loss", resume(full(".lock")), NO_SPACE + r".*s/\.lock"),
    Case("reconstruct-full-decoded", "data loss",
         on_session("reconstruct", full("recon/decoded/*")),
         NO_SPACE + r".*s/recon/decoded/frame_00000\.npy", ("s/recon", "s/recon/*"),
         check=status_is_failed),
    Case("reconstruct-full-after-frames", "data loss",
         on_session("reconstruct", full("recon/decoded/*", budget=40_000)),
         NO_SPACE + r".*s/recon/decoded/", ("s/recon", "s/recon/*"), check=status_is_failed),
    Case("reconstruct-full-status", "data loss", on_session("reconstruct", full("recon/*")),
         NO_SPACE + r".*s/recon/", ("s/recon", "s/recon/*")),
    Case("reconstruct-full-session", "data loss", on_session("reconstruct", full("", "*")),
         NO_SPACE + r".*s/\.lock"),
    Case("board-full-pdf", "data loss", board(full("*"), "--out", "OUT/b.pdf"),
         NO_SPACE + r".*b\.pdf"),
    Case("board-full-png", "data loss", board(full("*"), "--out", "OUT/b.png"),
         NO_SPACE + r".*b\.png"),
    Case("board-full-snippet", "data loss", board(full("*.yaml"), "--out", "OUT/b.pdf"),
         NO_SPACE + r".*b\.yaml", ("out/b.pdf",)),
    Case("board-full-measured", "data loss",
         board(full("*"), "--snippet", "OUT/old.yaml", "--measured-square-mm", "30"),
         r"old\.yaml"),
    Case("init-store-full", "data loss", calibrate(full("new-st", "new-st/*"), "init-store",
                                                   "TMP/new-st"), NO_SPACE + r".*new-st"),
    Case("init-store-full-midway", "data loss",
         calibrate(full("new-st/*", budget=30_000), "init-store", "TMP/new-st"),
         NO_SPACE + r".*new-st/"),
    Case("init-store-full-empty-folder", "data loss",
         calibrate(lambda t, f: ((t / "new-st").mkdir(), full("new-st/*")(t, f)), "init-store",
                   "TMP/new-st"), NO_SPACE + r".*new-st/"),
    Case("import-full", "data loss",
         calibrate(full("st/*"), "import", "TMP/spd.csv", "--kind", "light", "--name", "L2",
                   "--store", "ST"), NO_SPACE + r".*st/"),
    Case("import-full-index", "data loss",
         calibrate(full("st/.index.tmp.yaml"), "import", "TMP/spd.csv", "--kind", "light",
                   "--name", "L2", "--store", "ST"), NO_SPACE + r".*st/index\.yaml"),
    Case("import-full-new-store", "data loss",
         calibrate(full("st", "st/*"), "import", "TMP/spd.csv", "--kind", "light", "--name", "L2",
                   "--store", "ST", with_store=False), NO_SPACE + r".*st"),
    Case("show-plot-full", "data loss",
         calibrate(full("*.png"), "show", "LED1", "--store", "ST", "--plot", "TMP/p.png"),
         NO_SPACE + r".*p\.png"),
    Case("basis-out-full", "data loss",
         calibrate(full("*.npz"), "basis", "--out", "TMP/b.npz", "--plot", "TMP/b.png"),
         NO_SPACE + r".*b\.npz"),
    Case("basis-plot-full", "data loss",
         calibrate(full("*.png"), "basis", "--plot", "TMP/b.png"), NO_SPACE + r".*b\.png"),
    Case("select-plot-full", "data loss",
         calibrate(full("*.png"), "select", "--store", "ST", "--lights", "LED1",
                   "--camera", "cam", "--plot", "TMP/sel.png"), NO_SPACE + r".*sel\.png"),
]

CRASHES = [
    # read-only and foreign folders
    Case("reconstruct-read-only", "crash", on_session("reconstruct", read_only("", "*")),
         READ_ONLY),
    Case("resume-read-only", "crash", resume(read_only("", "*")), READ_ONLY),
    Case("reconstruct-read-only-recon", "crash",
         on_session("reconstruct", lambda s, f: ((s / "recon").mkdir(),
                                                 read_only("recon", "recon/*")(s, f))),
         r"s/recon.*read-only"),
    Case("capture-read-only-parent", "crash",
         capture_new(lambda t, f: ((t / "ro").mkdir(), read_only("ro", "ro/*")(t, f)), "ro/new"),
         READ_ONLY),
    Case("board-read-only", "crash", board(read_only("*"), "--out", "OUT/b.pdf"), READ_ONLY),
    Case("init-store-read-only", "crash", calibrate(read_only("new-st", "new-st/*"),
                                                    "init-store", "TMP/new-st"), READ_ONLY),
    Case("import-read-only", "crash",
         calibrate(read_only("st", "st/*"), "import", "TMP/spd.csv", "--kind", "light",
                   "--name", "L2", "--store", "ST"), READ_ONLY),
    Case("remove-read-only", "crash",
         calibrate(read_only("st", "st/*"), "remove", "LED1", "--store", "ST"), READ_ONLY),
    Case("reconstruct-no-permission", "crash", on_session("reconstruct", no_permission()), DENIED),
    Case("resume-no-permission", "crash", resume(no_permission()), DENIED),
    Case("board-no-permission", "crash", board(no_permission(), "--out", "OUT/b.pdf"), DENIED),
    Case("init-store-no-permission", "crash",
         calibrate(lambda t, f: ((t / "new-st").mkdir(), no_permission("new-st")(t, f)),
                   "init-store", "TMP/new-st"), DENIED),
    Case("import-no-permission", "crash",
         calibrate(no_permission("st"), "import", "TMP/spd.csv", "--kind", "light", "--name",
                   "L2", "--store", "ST"), DENIED),
    # a file where a folder should be, and the other way round
    Case("reconstruct-recon-a-file", "crash", on_session("reconstruct", a_file("recon")),
         r"s/recon is a file where a folder should be"),
    Case("reconstruct-decoded-a-file", "crash", on_session("reconstruct", a_file("recon/decoded")),
         r"s/recon/decoded is a file where a folder should be", ("s/recon/*",)),
    Case("reconstruct-manifest-a-folder", "crash", on_session("reconstruct", manifest_a_folder),
         r"manifest\.jsonl is not a file"),
    Case("resume-manifest-a-folder", "crash", on_session("resume", manifest_a_folder),
         r"manifest\.jsonl is not a file"),
    Case("verify-manifest-a-folder", "crash", on_session("verify", manifest_a_folder),
         r"manifest\.jsonl is not a file"),
    Case("info-manifest-a-folder", "crash", on_session("info", manifest_a_folder),
         r"manifest\.jsonl is not a file"),
    Case("store-variable-a-file", "crash",
         calibrate(lambda t, f: (write(t / "afile", "x"), f.monkeypatch.setenv(
             "SPECTRAL_RIG_STORE", str(t / "afile"))), "list", with_store=False),
         r"\$SPECTRAL_RIG_STORE .*afile is an existing file"),
    Case("import-store-under-a-file", "crash",
         calibrate(a_file("afile"), "import", "TMP/spd.csv", "--kind", "light", "--name", "L2",
                   "--store", "TMP/afile/st", with_store=False), r"afile is a file"),
]


def spd(tmp: Path, name: str, text: str) -> Path:
    return write(tmp / name, text)


def import_spd(text: str, kind: str = "light") -> Callable[[Path, Faults], list[str]]:
    def make(tmp: Path, faults: Faults) -> list[str]:
        path = spd(tmp, "x.csv", text)
        return ["calibrate", "import", str(path), "--kind", kind, "--name", "X", "--store",
                str(tmp / "st")]

    return make


def table(rows: list[tuple[float, str]], header: str = "wavelength_nm,power") -> str:
    return header + "\n" + "".join(f"{w:g},{v}\n" for w, v in rows)


HUGE = table([(w, "1e308" if w == 550 else "1") for w in W])


def store_entry_edited(text: str) -> Callable[[Path, Faults], list[str]]:
    """An entry's CSV replaced by ``text`` (and its hash updated, as a hand edit would not):
    only the values themselves are wrong."""

    def make(tmp: Path, faults: Faults) -> list[str]:
        root = store(tmp)
        index = yaml.safe_load((root / "index.yaml").read_text())
        entry = next(e for e in index["entries"] if e["name"] == "LED1")
        (root / entry["file"]).write_text(text)
        entry["sha256"] = hashlib.sha256(text.encode()).hexdigest()
        (root / "index.yaml").write_text(yaml.safe_dump(index, sort_keys=False))
        return ["calibrate", "select", "--store", str(root), "--lights", "LED1", "--camera",
                "cam", "--plot", str(tmp / "sel.png")]

    return make


def evaluate_truth(values: Callable[[int], np.ndarray]) -> Callable[[Path, Faults], list[str]]:
    """`rig evaluate` of a tiny reconstruction against a truth of ``values(vertices)``."""

    def make(tmp: Path, faults: Faults) -> list[str]:
        mesh = trimesh.creation.box()
        n = len(mesh.vertices)
        recon = tmp / "recon"
        recon.mkdir()
        np.savez(recon / "reflectance.npz", vertices=mesh.vertices, faces=mesh.faces,
                 wavelengths_nm=W, reflectance=np.full((n, W.size), 0.5))  # fmt: skip
        mesh.export(tmp / "gt.ply")
        np.save(tmp / "truth.npy", values(n))
        return ["evaluate", str(recon), "--gt-mesh", str(tmp / "gt.ply"), "--gt-reflectance",
                str(tmp / "truth.npy")]

    return make


def one_inf(n: int) -> np.ndarray:
    truth = np.full((n, W.size), 0.5)
    truth[3, 7] = np.inf
    return truth


NONSENSE = [
    Case("import-spd-1e308", "nonsense", import_spd(HUGE),
         r"x\.csv: value 1e\+308 at 550 nm.*±1e\+15"),
    Case("import-spd-minus-1e308", "nonsense",
         import_spd(table([(w, "-1e308" if w == 600 else "1") for w in W])),
         r"x\.csv: value .* at 600 nm is outside the allowed range"),
    Case("import-camera-1e308", "nonsense",
         import_spd(table([(w, "1,1e308,1") for w in W], "wavelength_nm,R,G,B"), "camera"),
         r"x\.csv: value 1e\+308"),
    Case("import-spd-micrometres", "nonsense",
         import_spd(table([(w / 1000, "1") for w in W], "wavelength_um,power")),
         r"x\.csv: wavelengths 0\.4–0\.7 look like micrometres .*convert them to nanometres"),
    Case("import-spd-angstrom", "nonsense",
         import_spd(table([(w * 10, "1") for w in W])), r"outside 100–3000 nm"),
    Case("select-spd-1e308-in-store", "nonsense", store_entry_edited(HUGE),
         r"value 1e\+308 at 550 nm"),
    Case("basis-from-micrometres", "nonsense",
         calibrate(lambda t, f: write(t / "um.csv", table([(w / 1000, "0.5") for w in W],
                                                         "wavelength_um,a")),
                   "basis", "--from", "TMP/um.csv", "--plot", "TMP/b.png"),
         r"um\.csv.*micrometres"),
    Case("select-reflectances-1e308", "nonsense",
         calibrate(lambda t, f: write(t / "r.csv", table([(w, "0.5,1e308") for w in W],
                                                        "wavelength_nm,a,b")),
                   "select", "--reflectances", "TMP/r.csv", "--plot", "TMP/sel.png"),
         r"r\.csv: value 1e\+308"),
    Case("reconstruct-iso-1e308", "nonsense", on_session("reconstruct",
                                                        edit_manifest(key("iso", 1e308, 2))),
         r"manifest\.jsonl line 3: frame 2: `iso` is 1e\+308, expected a positive number up to"),
    Case("resume-iso-1e308", "nonsense", on_session("resume", edit_manifest(key("iso", 1e308))),
         r"frame 0: `iso` is 1e\+308"),
    Case("verify-iso-1e308", "nonsense", on_session("verify", edit_manifest(key("iso", 1e308))),
         r"frame 0: `iso` is 1e\+308"),
    Case("reconstruct-exposure-1e308", "nonsense",
         on_session("reconstruct", edit_manifest(key("exposure_s", 1e308, 1))),
         r"frame 1: `exposure_s` is 1e\+308"),
    Case("reconstruct-duplicate-line", "nonsense", on_session("reconstruct",
                                                             edit_manifest(duplicate_line)),
         r"manifest\.jsonl: frame 0 appears 2 times"),
    Case("reconstruct-two-frames-one-file", "nonsense",
         on_session("reconstruct", edit_manifest(shared_file)),
         r"raw/v000_f00000_ambient\.dng is the file of frames 0, 1"),
    Case("resume-two-frames-one-file", "nonsense", on_session("resume", edit_manifest(shared_file)),
         r"is the file of frames 0, 1"),
    Case("verify-two-frames-one-file", "nonsense", on_session("verify", edit_manifest(shared_file)),
         r"duplicate +raw/v000_f00000_ambient\.dng is the file of frames 0, 1", code=1),
    Case("evaluate-truth-all-nan", "nonsense",
         evaluate_truth(lambda n: np.full((n, W.size), np.nan)),
         r"truth\.npy: 8 of 8 true spectra hold NaN or inf \(first: vertex 0\)"),
    Case("evaluate-truth-one-inf", "nonsense", evaluate_truth(one_inf),
         r"truth\.npy: 1 of 8 true spectra .*vertex 3"),
]

ESCAPES = [
    Case("verify-frame-link-out", "escape", on_session("verify", frame_link_out),
         r"link out +frame 1 .*raw/v000_f00001_LED1\.dng", code=1),
    Case("resume-frame-link-out", "escape", on_session("resume", frame_link_out),
         r"raw/v000_f00001_LED1\.dng \(frame 1\) " + LINK_OUT),
    Case("reconstruct-frame-link-out", "escape", on_session("reconstruct", frame_link_out),
         r"raw/v000_f00001_LED1\.dng \(frame 1\) " + LINK_OUT + r", to .*outside\.dng"),
    Case("reconstruct-manifest-link-out", "escape", on_session("reconstruct", manifest_link_out),
         r"s/manifest\.jsonl " + LINK_OUT),
    Case("verify-manifest-link-out", "escape", on_session("verify", manifest_link_out),
         r"s/manifest\.jsonl " + LINK_OUT),
    Case("info-manifest-link-out", "escape", on_session("info", manifest_link_out),
         r"s/manifest\.jsonl " + LINK_OUT),
    Case("calibrate-list-home-missing", "escape",
         lambda tmp, faults: ["calibrate", "list"], r"no calibration store at .*nohome",
         process=True),
    Case("board-home-missing", "escape",
         lambda tmp, faults: ["board", "--out", str(tmp / "b.txt")], r"b\.txt", process=True),
]

TABLE = DATA_LOSS + CRASHES + NONSENSE + ESCAPES


def snapshot(root: Path) -> dict[str, str]:
    """Every path under ``root`` (not following links) with what it is: a hash, a link's
    target, or a folder."""
    out: dict[str, str] = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            path = Path(folder) / name
            rel = path.relative_to(root).as_posix()
            if path.is_symlink():
                out[rel] = "link " + os.readlink(path)
            elif path.is_dir():
                out[rel] = "folder"
            else:
                out[rel] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def changed(before: dict[str, str], after: dict[str, str]) -> set[str]:
    return {p for p in before.keys() | after.keys() if before.get(p) != after.get(p)}


def run_process(argv: list[str], tmp: Path) -> tuple[int, str]:
    """``rig ARGV`` in its own process with HOME a folder that does not exist."""
    env = {**os.environ, "HOME": str(tmp / "nohome"), "PYTHONPATH": str(ROOT)}
    for name in ("XDG_CACHE_HOME", "XDG_CONFIG_HOME", "MPLCONFIGDIR", "NUMBA_CACHE_DIR",
                 "SPECTRAL_RIG_STORE"):
        env.pop(name, None)
    proc = subprocess.run([sys.executable, "-m", "rig.cli", *argv], capture_output=True,
                          text=True, env=env, cwd=ROOT, timeout=300)  # fmt: skip
    return proc.returncode, proc.stdout + proc.stderr


@pytest.fixture
def faults(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[Faults]:
    """Faults to inject, and a HOME inside the test's folder (so the snapshot covers it)."""
    home = tmp_path / "home"
    (home / ".cache").mkdir(parents=True)
    (home / ".config").mkdir()
    monkeypatch.setenv("HOME", str(home))
    for name in ("SPECTRAL_RIG_STORE", "MPLCONFIGDIR", "NUMBA_CACHE_DIR"):
        monkeypatch.delenv(name, raising=False)  # restored after the row: main() may set them
    injected = Faults(monkeypatch)
    yield injected
    injected.restore_permissions()


def test_the_table_is_large_enough() -> None:
    assert len(TABLE) >= 50
    assert len({case.id for case in TABLE}) == len(TABLE)


@pytest.mark.parametrize("case", TABLE, ids=[case.id for case in TABLE])
def test_file_system_failure_is_one_clear_line(
    case: Case,
    base_session: Path,
    tmp_path: Path,
    faults: Faults,
    capsys: pytest.CaptureFixture[str],
) -> None:
    BASE[:] = [base_session]
    argv = case.make(tmp_path, faults)
    before = snapshot(tmp_path)
    if case.process:
        code, text = run_process(argv, tmp_path)
    else:
        code, text = run_cli(argv, capsys)
    faults.monkeypatch.undo()  # the faults end with the command (and HOME with them)
    faults.restore_permissions()
    assert code == case.code, text
    assert "internal error" not in text and "Traceback" not in text, text
    errors = [line for line in text.splitlines() if "error:" in line]
    if case.code == 2:
        assert len(errors) == 1, text  # one line, not a usage block or a wrapped message
        assert re.search(case.expect, errors[0]), text
    else:  # `rig session verify`: its report lines, no error line
        assert not errors and re.search(case.expect, text), text
    unexpected = {
        p for p in changed(before, snapshot(tmp_path))
        if not any(fnmatch(p, glob) for glob in case.may_change)
    }
    assert not unexpected, f"changed outside the row's outputs: {sorted(unexpected)}\n{text}"
    if case.check is not None:
        case.check(tmp_path)

