"""Bad inputs of the capture side (manifest, session.yaml, calibration store, device
transports) through `rig` itself: each gives a non-zero exit and one message naming the file,
line, key or device — never "internal error". The rest of the issue-17 table (profiles, CLI
arguments, reconstruction) is tests/rig/test_bad_inputs.py."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml
from lockholder import hold, release_all
from simrig import PROFILE, capture_small_session

from calibration.store import CalibrationStore
from rig.cli import main

pytest.importorskip("drivers.sim")
ROOT = Path(__file__).parents[3]
Prepare = Callable[[Path, Path], list[str]]  # (copy of the base session, tmp dir) -> argv


@dataclass(frozen=True)
class Case:
    name: str
    prepare: Prepare
    code: int
    says: tuple[str, ...]  # every one must appear in the output (whitespace-normalised)


@pytest.fixture(scope="module")
def base_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return capture_small_session(tmp_path_factory.mktemp("base") / "s")


# -- manifest ---------------------------------------------------------------------------------
def edit_line(key: str, value: object, line: int = 1) -> Callable[[Path], None]:
    def edit(session: Path) -> None:
        manifest = session / "manifest.jsonl"
        lines = manifest.read_text().splitlines()
        data = json.loads(lines[line - 1])
        if value is DROP:
            data.pop(key)
        elif key.startswith("extra."):
            data["extra"][key[6:]] = value
        else:
            data[key] = value
        lines[line - 1] = json.dumps(data)
        manifest.write_text("\n".join(lines) + "\n")

    return edit


DROP = object()


def resume_after(edit: Callable[[Path], None]) -> Prepare:
    def prepare(session: Path, tmp: Path) -> list[str]:
        edit(session)
        return ["capture", "--resume", str(session), "--yes"]

    return prepare


def verify_after(edit: Callable[[Path], None]) -> Prepare:
    def prepare(session: Path, tmp: Path) -> list[str]:
        edit(session)
        return ["session", "verify", str(session)]

    return prepare


def reconstruct_after(edit: Callable[[Path], None]) -> Prepare:
    def prepare(session: Path, tmp: Path) -> list[str]:
        edit(session)
        return ["reconstruct", str(session)]

    return prepare


def raw_line(data: bytes, at: int = 3) -> Callable[[Path], None]:
    def edit(session: Path) -> None:
        manifest = session / "manifest.jsonl"
        lines = manifest.read_bytes().splitlines(keepends=True)
        manifest.write_bytes(b"".join(lines[: at - 1]) + data + b"".join(lines[at - 1 :]))

    return edit


def garbage_last_line(session: Path) -> None:
    """A complete (newline-ended) bad last line is no torn write: it is reported, not skipped."""
    manifest = session / "manifest.jsonl"
    manifest.write_bytes(manifest.read_bytes() + b"garbage\n")


def duplicate_line(session: Path) -> None:
    manifest = session / "manifest.jsonl"
    manifest.write_bytes(manifest.read_bytes() + manifest.read_bytes().splitlines(True)[0])


def remove_frame_file(session: Path) -> None:
    (
        session / json.loads((session / "manifest.jsonl").read_text().splitlines()[0])["path"]
    ).unlink()


def change_frame_file(session: Path) -> None:
    path = session / json.loads((session / "manifest.jsonl").read_text().splitlines()[1])["path"]
    path.write_bytes(path.read_bytes()[:-1] + b"\x00")


def stray_file(session: Path) -> None:
    (session / "raw" / "IMG_9999.CR2").write_bytes(b"not from this session")


LINE = "manifest.jsonl line 1:"
MANIFEST_CASES = [
    Case(
        "frame not a number", resume_after(edit_line("frame", "abc")), 2, (LINE, "`frame` is 'abc'")
    ),
    Case("frame negative", verify_after(edit_line("frame", -1)), 2, (LINE, "`frame` is -1")),
    Case("frame a boolean", verify_after(edit_line("frame", True)), 2, (LINE, "`frame` is True")),
    Case("frame a float", verify_after(edit_line("frame", 1.5)), 2, (LINE, "`frame` is 1.5")),
    Case(
        "view beyond the plan",
        resume_after(edit_line("view", 99)),
        2,
        (LINE, "`view` is 99", "0..1"),
    ),
    Case(
        "view beyond the plan (reconstruct)",
        reconstruct_after(edit_line("view", 99)),
        2,
        (LINE, "`view` is 99", "0..1"),
    ),
    Case(
        "view beyond the plan (verify)",
        verify_after(edit_line("view", 99)),
        1,
        ("off-plan", "view 99"),
    ),
    Case("view a string", verify_after(edit_line("view", "x")), 2, (LINE, "`view` is 'x'")),
    Case(
        "illumination a number",
        verify_after(edit_line("illumination", 5)),
        2,
        (LINE, "`illumination`"),
    ),
    Case(
        "path climbs out",
        resume_after(edit_line("path", "../../x.dng")),
        2,
        (LINE, "`path`", "no `..`"),
    ),
    Case(
        "path absolute", verify_after(edit_line("path", "/etc/passwd")), 2, (LINE, "'/etc/passwd'")
    ),
    Case("path a drive", verify_after(edit_line("path", "C:\\raw\\a.dng")), 2, (LINE, "`path`")),
    Case("path empty", verify_after(edit_line("path", "")), 2, (LINE, "`path` is ''")),
    Case("sha256 not hex", verify_after(edit_line("sha256", "xyz")), 2, (LINE, "`sha256`", "64")),
    Case(
        "exposure a word", verify_after(edit_line("exposure_s", "fast")), 2, (LINE, "`exposure_s`")
    ),
    Case(
        "exposure negative",
        verify_after(edit_line("exposure_s", -1)),
        2,
        (LINE, "`exposure_s` is -1"),
    ),
    Case("iso NaN", verify_after(edit_line("iso", float("nan"))), 2, (LINE, "`iso` is nan")),
    Case(
        "timestamp a number", verify_after(edit_line("timestamp", 7)), 2, (LINE, "`timestamp` is 7")
    ),
    Case("sha256 missing", verify_after(edit_line("sha256", DROP)), 2, ("line 1 lacks sha256",)),
    Case("line a list", verify_after(raw_line(b"[1, 2]\n")), 2, ("line 3 is not a JSON object",)),
    Case("binary line", resume_after(raw_line(b"\xff\xfe\x00\x01\n")), 2, ("line 3 is not text",)),
    Case(
        "binary line (verify)", verify_after(raw_line(b"\x89PNG\x00\n")), 2, ("line 3 is not text",)
    ),
    Case("broken JSON", verify_after(raw_line(b'{"frame": \n')), 2, ("line 3 is not valid JSON",)),
    Case(
        "companion climbs out",
        verify_after(edit_line("extra.other_files", [{"path": "../x.jpg", "sha256": "0" * 64}])),
        2,
        (LINE, "other_files[0].path"),
    ),
    Case(
        "companions not a list",
        verify_after(edit_line("extra.other_files", "x")),
        2,
        (LINE, "`other_files`"),
    ),
    Case("extra not an object", verify_after(edit_line("extra", [1])), 2, (LINE, "`extra`")),
    Case(
        "complete bad last line", resume_after(garbage_last_line), 2, ("line 9 is not valid JSON",)
    ),
    Case("frame listed twice", resume_after(duplicate_line), 2, ("lists frame 0 twice",)),
    Case("frame listed twice (verify)", verify_after(duplicate_line), 1, ("duplicate", "frame 0")),
    Case(
        "illumination not the plan's",
        resume_after(edit_line("illumination", "LED9", 2)),
        2,
        ("frame 1 is recorded as view 0, 'LED9' but the plan has view 0, LED1",),
    ),
    Case(
        "frame beyond the plan",
        resume_after(edit_line("frame", 999)),
        2,
        ("frame 999", "no such frame"),
    ),
    Case(
        "frame file missing", resume_after(remove_frame_file), 2, ("missing from raw/", "frame 0")
    ),
    Case("frame file missing (verify)", verify_after(remove_frame_file), 1, ("missing", "frame 0")),
    Case(
        "frame file changed (verify)",
        verify_after(change_frame_file),
        1,
        ("hash mismatch", "frame 1"),
    ),
    Case("stray file (verify)", verify_after(stray_file), 1, ("orphan", "raw/IMG_9999.CR2")),
]


# -- session.yaml and the session folder ---------------------------------------------------------
def session_yaml(edit: Callable[[dict], object]) -> Callable[[Path], None]:
    def apply(session: Path) -> None:
        info = yaml.safe_load((session / "session.yaml").read_text())
        edit(info)
        (session / "session.yaml").write_text(yaml.safe_dump(info, sort_keys=False))

    return apply


def light_transport(transport: dict) -> Callable[[dict], object]:
    return lambda info: info["profile"]["devices"].update(
        light={"driver": "rgbcw-serial", "transport": transport}
    )


def binary_session_yaml(session: Path) -> None:
    (session / "session.yaml").write_bytes(b"\x00\xff\xfe binary")


def new_into(what: str) -> Prepare:
    def prepare(session: Path, tmp: Path) -> list[str]:
        target = tmp / "target"
        if what == "session":
            target = session
        else:
            target.mkdir()
            (target / "holiday.jpg").write_bytes(b"x")
        return ["capture", "--yes", "--profile", str(PROFILE), "--out", str(target)]

    return prepare


def resume_folder(what: str) -> Prepare:
    def prepare(session: Path, tmp: Path) -> list[str]:
        target = tmp / "target"
        if what == "foreign":
            target.mkdir()
            (target / "thesis.pdf").write_bytes(b"x")
            return ["capture", "--yes", "--profile", str(PROFILE), "--resume", str(target)]
        return ["capture", "--yes", "--resume", str(target)]

    return prepare


def held_by(command: str, argv: Callable[[Path], list[str]]) -> Prepare:
    """The session locked by another process running ``command``, then ``argv``."""

    def prepare(session: Path, tmp: Path) -> list[str]:
        hold(session, command)
        return argv(session)

    return prepare


def lock_file(kind: str, argv: Callable[[Path], list[str]]) -> Prepare:
    """SESSION/.lock left by a dead process, or replaced by a folder or a link out."""

    def prepare(session: Path, tmp: Path) -> list[str]:
        lock = session / ".lock"
        if kind == "dead":
            gone = subprocess.Popen(["true"])
            gone.wait()
            record = {"pid": gone.pid, "host": "here", "command": "rig capture", "since": "x"}
            lock.write_text(json.dumps(record))
        elif kind == "folder":
            lock.mkdir()
        elif kind == "hard link":  # writing the holder into it would change the victim
            (tmp / "victim.csv").write_text("precious")
            os.link(tmp / "victim.csv", lock)
        else:
            (tmp / "victim.csv").write_text("precious")
            lock.symlink_to(tmp / "victim.csv")
        return argv(session)

    return prepare


def resume(session: Path) -> list[str]:
    return ["capture", "--resume", str(session), "--yes"]


def reconstruct(session: Path) -> list[str]:
    return ["reconstruct", str(session)]


def new_capture(session: Path) -> list[str]:
    return ["capture", "--yes", "--profile", str(PROFILE), "--out", str(session)]


IN_USE = "wait for it to finish, or stop it"
LOCK_CASES = [
    Case(
        "resume while captured",
        held_by("rig capture", resume),
        2,
        ("in use by `rig capture`", IN_USE),
    ),
    Case(
        "reconstruct while captured",
        held_by("rig capture --resume", reconstruct),
        2,
        ("in use by `rig capture --resume` (PID", IN_USE),
    ),
    Case(
        "resume while reconstructed",
        held_by("rig reconstruct", resume),
        2,
        ("in use by `rig reconstruct`", IN_USE),
    ),
    Case("new capture into a held folder", held_by("rig capture", new_capture), 2, (IN_USE,)),
    Case("lock file of a dead process", lock_file("dead", resume), 0, ("capture complete",)),
    Case("lock file a folder", lock_file("folder", resume), 2, ("cannot open the lock file",)),
    Case("lock file a link out", lock_file("link", resume), 2, ("cannot open the lock file",)),
    Case("lock file a hard link", lock_file("hard link", resume), 2, ("has other names",)),
    Case(
        "lock file a link out (reconstruct)",
        lock_file("link", reconstruct),
        2,
        ("cannot open the lock file", ".lock"),
    ),
]

SESSION_CASES = [
    Case("session.yaml binary", resume_after(binary_session_yaml), 2, ("session.yaml",)),
    Case(
        "session.yaml without a profile",
        resume_after(session_yaml(lambda info: info.pop("profile"))),
        2,
        ("session.yaml has no profile snapshot",),
    ),
    Case(
        "snapshot runs a program",
        resume_after(session_yaml(light_transport({"type": "subprocess", "command": "rm -rf ~"}))),
        2,
        ("session.yaml: devices.light runs `rm -rf ~`", "--trust-session-devices"),
    ),
    Case(
        "snapshot records to a file",
        resume_after(session_yaml(light_transport({"type": "serial", "record": "/etc/x"}))),
        2,
        ("devices.light writes /etc/x", "--trust-session-devices"),
    ),
    Case(
        "--out holds a session",
        new_into("session"),
        2,
        ("already holds a capture session", "--resume"),
    ),
    Case("--out not empty", new_into("folder"), 2, ("exists and is not empty",)),
    Case(
        "--resume a foreign folder",
        resume_folder("foreign"),
        2,
        ("is not a capture session", "thesis.pdf"),
    ),
    Case(
        "--resume nothing", resume_folder("missing"), 2, ("has no session to resume", "--profile")
    ),
]


# -- calibration store ----------------------------------------------------------------------
def store_with(edit: Callable[[dict, Path], None], command: str = "remove") -> Prepare:
    def prepare(session: Path, tmp: Path) -> list[str]:
        root = tmp / "deep" / "store"
        store = CalibrationStore(root)
        w = np.arange(400.0, 701.0, 10.0)
        store.add_light("LED1", w, np.ones_like(w), {"source": "test"})
        store.add_camera("cam", w, np.ones((w.size, 3)), {"source": "test"})
        (tmp / "victim.csv").write_text("precious")
        index = yaml.safe_load((root / "index.yaml").read_text())
        edit(index, root)
        (root / "index.yaml").write_text(yaml.safe_dump(index, sort_keys=False))
        if command == "remove":
            return ["calibrate", "remove", "LED1", "--all", "--store", str(root)]
        return ["calibrate", "list", "--store", str(root)]

    return prepare


def entry(key: str, value: object) -> Callable[[dict, Path], None]:
    return lambda index, root: index["entries"][0].update({key: value})


def escaping_link(index: dict, root: Path) -> None:
    os.symlink(root.parents[1] / "victim.csv", root / "lights" / "escape.csv")
    index["entries"][0]["file"] = "lights/escape.csv"


def edited_csv(index: dict, root: Path) -> None:
    path = root / index["entries"][0]["file"]
    text = path.read_text()
    assert ",1\n" in text
    path.write_text(text.replace(",1\n", ",2\n", 1))


def capture_with_store(edit: Callable[[dict, Path], None]) -> Prepare:
    def prepare(session: Path, tmp: Path) -> list[str]:
        store_with(edit)(session, tmp)
        profile = yaml.safe_load(PROFILE.read_text())
        profile["calibration"] = {
            "store": str(tmp / "deep" / "store"),
            "camera": "cam",
            "lights": {"LED1": "LED1", "LED2": "LED1", "LED3": "LED1"},
        }
        (tmp / "p.yaml").write_text(yaml.safe_dump(profile))
        return ["capture", "--yes", "--profile", str(tmp / "p.yaml"), "--out", str(tmp / "new")]

    return prepare


INSIDE = "not a file inside the store"
STORE_CASES = [
    Case(
        "file climbs out",
        store_with(entry("file", "../../victim.csv")),
        2,
        ("'../../victim.csv'", INSIDE),
    ),
    Case("file absolute", store_with(entry("file", "/etc/passwd")), 2, ("'/etc/passwd'", INSIDE)),
    Case("file a symlink out", store_with(escaping_link), 2, ("'lights/escape.csv'", INSIDE)),
    Case("file a number", store_with(entry("file", 5), "list"), 2, ("file: 5", INSIDE)),
    Case("file empty", store_with(entry("file", ""), "list"), 2, ("file: ''", INSIDE)),
    Case(
        "capture with a store pointing out",
        capture_with_store(entry("file", "../../victim.csv")),
        2,
        (INSIDE,),
    ),
    Case("entry kind unknown", store_with(entry("kind", "lamp"), "list"), 2, ("has kind 'lamp'",)),
    Case(
        "entry version a word", store_with(entry("version", "two"), "list"), 2, ("version 'two'",)
    ),
    Case(
        "entry with an unknown key",
        store_with(entry("colour", "red"), "list"),
        2,
        ("entry 1 is malformed",),
    ),
    Case(
        "index of another format",
        store_with(lambda index, root: index.update(format="other/1"), "list"),
        2,
        ("is not a spectral-rig calibration index",),
    ),
    Case(
        "spectrum edited in place",
        capture_with_store(edited_csv),
        2,
        ("was modified after it was added", "LED1"),
    ),
]


# -- device transports --------------------------------------------------------------------------
def capture_with_light(light: dict) -> Prepare:
    def prepare(session: Path, tmp: Path) -> list[str]:
        profile = yaml.safe_load(PROFILE.read_text())
        profile["devices"]["light"] = light
        (tmp / "p.yaml").write_text(yaml.safe_dump(profile))
        return ["capture", "--yes", "--profile", str(tmp / "p.yaml"), "--out", str(tmp / "new")]

    return prepare


def rgbcw(transport: dict) -> dict:
    return {"driver": "rgbcw-serial", "transport": transport, "boot_tries": 1}


PY = sys.executable
DEVICE_CASES = [
    Case(
        "bridge program missing",
        capture_with_light(rgbcw({"type": "subprocess", "command": "/nonexistent/bridge"})),
        2,
        ("program '/nonexistent/bridge' not found",),
    ),
    Case(
        "bridge exits",
        capture_with_light(rgbcw({"type": "subprocess", "command": [PY, "-c", "exit(4)"]})),
        2,
        ("helper program", "-c exit(4)` exited with status 4"),
    ),
    Case(
        "bridge speaks another protocol",
        capture_with_light(rgbcw({"type": "subprocess", "command": "cat"})),
        2,
        ("answered 'ID?' to ID?", "rgbcw-text/1"),
    ),
    Case(
        "subprocess without a command",
        capture_with_light(rgbcw({"type": "subprocess"})),
        2,
        ("rgbcw-serial.transport", "unexpected or missing keys"),
    ),
    Case(
        "unknown transport type",
        capture_with_light(rgbcw({"type": "carrier-pigeon"})),
        2,
        ("unknown transport type 'carrier-pigeon'",),
    ),
    Case(
        "tcp port a word",
        capture_with_light(
            {"driver": "magic-home", "transport": {"host": "127.0.0.1", "port": "http"}}
        ),
        2,
        ("magic-home.transport", "bad value"),
    ),
    Case(
        "serial port missing",
        capture_with_light(rgbcw({"type": "serial", "port": "/dev/nonexistent-tty"})),
        2,
        ("/dev/nonexistent-tty",),
    ),
]

CASES = MANIFEST_CASES + SESSION_CASES + LOCK_CASES + STORE_CASES + DEVICE_CASES


@pytest.fixture(autouse=True)
def _end_lock_holders() -> Iterator[None]:
    yield
    release_all()


def test_the_table_is_large_enough() -> None:
    assert len(CASES) >= 40 and len({c.name for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_bad_input_is_one_clear_error(
    case: Case,
    base_session: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(ROOT)
    session = tmp_path / "s"
    shutil.copytree(base_session, session)
    argv = case.prepare(session, tmp_path)
    code = main(argv)
    captured = capsys.readouterr()
    text = " ".join((captured.out + captured.err).split())
    assert code == case.code, text
    assert "internal error" not in text.lower() and "Traceback" not in text
    for phrase in case.says:
        assert " ".join(phrase.split()) in text
    if code == 2:  # a RigError: one `error:` line naming the problem and the fix
        assert text.count("error:") == 1
    victim = tmp_path / "victim.csv"
    assert not victim.exists() or victim.read_text() == "precious"
