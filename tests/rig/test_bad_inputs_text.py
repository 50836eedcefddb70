"""The bad-input table, part two (issue 34): user text that rich would read as markup, names
holding newlines, escape sequences or bidirectional overrides, numbers beyond any sensible
bound, and messages that suggested an impossible fix. Each row runs the real CLI
(`rig.cli.main`) as tests/rig/test_bad_inputs.py does and expects a non-zero exit, one error
line matching `expect`, neither an internal error nor a traceback, and not one byte changed
under the test's folder (every file and folder hashed before and after)."""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import yaml
from lockholder import release_all
from simrig import PROFILE
from test_bad_inputs import BINARY, SIM, Case, config, profile, run_cli, write

from rig.cli import main

NL = "\n"
SMALL = PROFILE.read_text()  # the tiny sim profile: capture rows fail before any frame


def argv(*args: str) -> Callable[[Path], list[str]]:
    """A command line with TMP standing for the test's folder."""
    return lambda tmp: [a.replace("TMP", str(tmp)) for a in args]


def with_file(name: str, text: str | bytes, *args: str) -> Callable[[Path], list[str]]:
    """``TMP/name`` written first, then the command line."""

    def make(tmp: Path) -> list[str]:
        write(tmp / name, text)
        return argv(*args)(tmp)

    return make


def small_with(old: str, new: str) -> str:
    assert old in SMALL
    return SMALL.replace(old, new)


# -- user text: markup, newlines, escape sequences, bidi controls in paths and names -----------
TEXT = [
    Case("text-profile-markup-newline-missing",
         argv("capture", "--profile", "TMP/a[/x]\nb.yaml", "--out", "TMP/o", "--yes"),
         r"a\[/x\]\\nb\.yaml does not exist"),
    Case("text-profile-ansi-escape-binary",
         with_file("\x1b[31mred.yaml", BINARY, "capture", "--profile", "TMP/\x1b[31mred.yaml",
                   "--out", "TMP/o", "--yes"),
         r"\\x1b\[31mred\.yaml.*not UTF-8"),
    Case("text-profile-bidi-override", profile(SIM + "plna: 1\n", name="p\u202egnp.yaml"),
         r"p\\u202egnp\.yaml.*'plna'"),
    Case("text-capture-out-under-markup-file",
         with_file("f[bold]\n", "x", "capture", "--profile", "sim", "--out", "TMP/f[bold]\n/s",
                   "--yes"),
         r"--out .*f\[bold\]\\n is a file"),
    Case("text-capture-resume-markup", argv("capture", "--resume", "TMP/s[/x]", "--yes"),
         r"s\[/x\] has no session to resume"),
    Case("text-session-info-markup-newline", argv("session", "info", "TMP/nowhere[/x]\n"),
         r"nowhere\[/x\]\\n is not a session directory"),
    Case("text-session-verify-tab-markup", argv("session", "verify", "TMP/[red]s\tx"),
         r"\[red\]s\\tx is not a session directory"),
    Case("text-session-yaml-in-markup-folder",
         with_file("s[/x]/session.yaml", "rig: sim\nrig: real\n", "reconstruct", "TMP/s[/x]"),
         r"s\[/x\]/session\.yaml.*duplicate key 'rig'"),
    Case("text-reconstruct-carriage-return", argv("reconstruct", "TMP/[/]s\rx"),
         r"\[/\]s\\rx is not a session directory"),
    Case("text-reconstruct-config-markup-binary",
         lambda tmp: [*config(BINARY)(tmp)[:-1], str(write(tmp / "c[/x]\n.yaml", BINARY))],
         r"c\[/x\]\\n\.yaml.*not UTF-8"),
    Case("text-reconstruct-initial-mesh-markup",
         lambda tmp: ["reconstruct", str(write(tmp / "s" / "session.yaml", "rig: sim\n").parent),
                      "--initial-mesh", str(tmp / "m[/x]\n.ply")],
         r"--initial-mesh .*m\[/x\]\\n\.ply is not a file"),
    Case("text-config-unknown-section-markup", config("'[/x]\\n': {}\n"),
         r"c\.yaml: unknown section\(s\) \[/x\]\\n — use decode"),
    Case("text-config-value-escape-sequence", config('optimise: {light_mode: "\\e[2J"}\n'),
         r"light_mode.*\\x1b\[2J"),
    Case("text-view-markup-newline", argv("view", "TMP/v[/x]\n"),
         r"v\[/x\]\\n holds no reflectance\.npz"),
    Case("text-view-export-markup-folder",
         lambda tmp: ["view", str(tmp), "--export", str(_mkdir(tmp / "[/x]dir"))],
         r"--export .*\[/x\]dir is a folder"),
    Case("text-relight-out-markup-folder",
         lambda tmp: ["relight", str(tmp / "s"), "--view", "0", "--out",
                      str(_mkdir(tmp / "[/o]\n"))],
         r"--out .*\[/o\]\\n is a folder"),
    Case("text-relight-camera-markup-duplicate",
         with_file("cam[/x]\n.yaml", "width: 64\nwidth: 32\n", "relight", "TMP/s", "--camera",
                   "TMP/cam[/x]\n.yaml"),
         r"cam\[/x\]\\n\.yaml.*duplicate key 'width'"),
    Case("text-relight-markup-session", argv("relight", "TMP/e[/x]\u2028", "--view", "0"),
         r"e\[/x\]\\u2028/recon/reflectance\.npz"),
    Case("text-export-markup-session", argv("export", "TMP/e[/x]\n", "--glb", "TMP/o.glb"),
         r"e\[/x\]\\n holds no reflectance\.npz"),
    Case("text-export-glb-markup-name", argv("export", "TMP/e", "--glb", "TMP/m[/x]\n.txt"),
         r"--glb .*m\[/x\]\\n\.txt is not a \.glb"),
    Case("text-evaluate-markup-session",
         argv("evaluate", "TMP/ev[/x]\n", "--gt-mesh", "TMP/m.ply", "--gt-reflectance",
              "TMP/r.npy"),
         r"ev\[/x\]\\n"),
    Case("text-calibrate-store-markup-file",
         with_file("st[/x]\n", "x", "calibrate", "list", "--store", "TMP/st[/x]\n"),
         r"--store .*st\[/x\]\\n is an existing file"),
    Case("text-calibrate-store-markup-missing",
         argv("calibrate", "list", "--store", "TMP/new[/x]"),
         r"no calibration store at .*new\[/x\] — create one with `rig calibrate init-store "
         r".*new\[/x\]`"),
    Case("text-calibrate-import-markup-missing",
         argv("calibrate", "import", "TMP/s[/x]\n.csv", "--kind", "light", "--name", "X"),
         r"s\[/x\]\\n\.csv does not exist"),
    Case("text-calibrate-import-osc-binary",
         with_file("\x1b]0;title\x07.txt", BINARY, "calibrate", "import",
                   "TMP/\x1b]0;title\x07.txt", "--kind", "light", "--name", "X"),
         r"\\x1b\]0;title\\x07\.txt is a binary file"),
    Case("text-calibrate-import-name-markup",
         with_file("s.csv", "wavelength_nm,power\n" + "".join(f"{w},1\n" for w in range(400, 710,
                                                                                        10)),
                   "calibrate", "import", "TMP/s.csv", "--kind", "light", "--name", "[/x]"),
         r"invalid calibration entry name '\[/x\]'"),
    Case("text-calibrate-import-name-newline",
         with_file("s.csv", "wavelength_nm,power\n" + "".join(f"{w},1\n" for w in range(400, 710,
                                                                                        10)),
                   "calibrate", "import", "TMP/s.csv", "--kind", "light", "--name", "LED\n1"),
         r"invalid calibration entry name 'LED\\n1'"),
    Case("text-calibrate-show-markup-entry",
         lambda tmp: ["calibrate", "show", "[/x]\nLED", "--store", _store(tmp)],
         r"\[/x\]\\nLED"),
    Case("text-calibrate-remove-markup-entry",
         lambda tmp: ["calibrate", "remove", "LED[bold]1", "--store", _store(tmp)],
         r"LED\[bold\]1"),
    Case("text-board-out-markup-suffix", argv("board", "--out", "TMP/b[/x]\n.txt"),
         r"b\[/x\]\\n\.txt"),
    Case("text-board-snippet-markup-missing",
         argv("board", "--snippet", "TMP/sn[/x]\n.yaml", "--measured-square-mm", "30"),
         r"sn\[/x\]\\n\.yaml does not exist"),
    Case("text-batch-list-markup-missing", argv("batch", "--list", "TMP/l[/x]\n.txt"),
         r"--list .*l\[/x\]\\n\.txt"),
    Case("text-illumination-name-markup",
         profile(SIM.replace("LED2:", "'L[/x]':").replace("illuminations: all}",
                                                            "illuminations: [LED3]}")),
         r"key 'illuminations\.L\[/x\]' is not a usable name"),
    Case("text-illumination-name-newline",
         profile(SIM.replace("LED2:", '"L\\nX":').replace("illuminations: all}",
                                                            "illuminations: [LED3]}")),
         r"key 'illuminations\.L\\nX' is not a usable name"),
    Case("text-profile-unknown-key-markup", profile(SIM + "'[/plna]': 1\n"),
         r"p\.yaml: key '\[/plna\]' is not known"),
    Case("text-profile-key-zero-width-space", profile(SIM + '"pl\\u200ban": 1\n'),
         r"p\.yaml: key 'pl\\u200ban' is not known"),
    Case("text-driver-name-markup-newline",
         profile(SIM.replace("light: {driver: sim}", 'light: {driver: "[red]nosuch\\n"}')),
         r"devices\.light\.driver.*\[red\]nosuch\\n"),
    Case("text-cli-unknown-command-markup", argv("recon[/x]\nstruct", "TMP"),
         r"recon\[/x\]\\nstruct"),
    Case("text-cli-unrecognised-argument-newline", argv("session", "info", "TMP", "--fast\nx"),
         r"unrecognized arguments: --fast\\nx"),
]


# -- numbers with no sensible upper bound, refused before any work ------------------------------
NUMBERS = [
    Case("bound-camera-settings-exposure",
         profile(SIM + "camera_settings: {exposure_s: 1.0e+308}\n"),
         r"p\.yaml: key 'camera_settings\.exposure_s' is 1e\+308 .*<= 3600"),
    Case("bound-camera-settings-iso", profile(SIM + "camera_settings: {iso: 1.0e+12}\n"),
         r"p\.yaml: key 'camera_settings\.iso'.*<= 1e\+06"),
    Case("bound-sim-camera-huge-not-cable",
         profile(small_with("width: 64, height: 48", "width: 100000, height: 100000")),
         r"^(?!.*cable).*p\.yaml: key 'sim\.camera\.width' is 100000 .*\[32, 16384\]"),
    Case("bound-sim-subdivisions", profile(small_with("subdivisions: 3", "subdivisions: 12")),
         r"p\.yaml: key 'sim\.subdivisions' is 12 .*\[0, 8\]"),
    Case("bound-sim-scene-seed-negative", profile(small_with("subdivisions: 3",
                                                             "subdivisions: 3\n  scene_seed: -1")),
         r"sim\.scene_seed"),
    Case("bound-sim-illumination-level",
         profile(small_with("subdivisions: 3", "subdivisions: 3\n  illuminations: "
                                               "{LED1: {c: 50}}")),
         r"sim\.illuminations\.LED1\.c"),
    Case("bound-plan-views-billion", profile(SIM.replace("views: 4", "views: 1000000000")),
         r"plan\.views' is 1000000000 .*\[1, 1000\]"),
    Case("bound-driver-timeout-inf",
         profile(SIM.replace("camera: {driver: sim}",
                             "camera: {driver: folder-watch, folder: x, timeout_s: .inf}")),
         r"camera driver 'folder-watch': key 'timeout_s' is inf .*<= 86400"),
    Case("bound-driver-settle-huge",
         profile(SIM.replace("camera: {driver: sim}",
                             "camera: {driver: folder-watch, folder: x, stable_s: 1.0e+9}")),
         r"key 'stable_s'.*\[0, 3600\]"),
    Case("bound-transport-tcp-port",
         profile(SIM.replace("light: {driver: sim}", "light: {driver: magic-home, transport: "
                             "{type: tcp, host: 127.0.0.1, port: 99999}}")),
         r"magic-home\.transport.*key 'port' is 99999 .*\[1, 65535\]"),
    Case("bound-transport-timeout",
         profile(SIM.replace("light: {driver: sim}", "light: {driver: magic-home, transport: "
                             "{type: tcp, host: 127.0.0.1, port: 5577, timeout_s: 1.0e+308}}")),
         r"key 'timeout_s'.*<= 3600"),
    Case("bound-transport-usb-id",
         profile(SIM.replace("light: {driver: sim}", "light: {driver: velleman-k8062, "
                             "transport: {type: hid, vid: 0x10000, pid: 1}}")),
         r"transport\.vid = 65536 is not a USB id"),
    Case("bound-capture-seed-negative-not-cable",
         argv("capture", "--profile", "sim", "--out", "TMP/o", "--yes", "--seed", "-1"),
         r"^(?!.*cable).*argument --seed: -1 is not allowed .*\[0, 1e\+09\]"),
    Case("bound-demo-views-billion", argv("demo", "--out", "TMP/d", "--views", "1000000000"),
         r"--views 1000000000 is out of range .*\[6, 1000\]"),
    Case("bound-demo-seed-word", argv("demo", "--out", "TMP/d", "--seed", "1e3"),
         r"argument --seed: 1e3"),
    Case("bound-relight-view-negative", argv("relight", "TMP/s", "--view", "-1"),
         r"argument --view: -1 .*\[0, 999\]"),
    Case("bound-relight-exposure-huge", argv("relight", "TMP/s", "--view", "0", "--exposure",
                                             "1e308"),
         r"argument --exposure: 1e308 .*<= 1000"),
    Case("bound-select-noise-huge", argv("calibrate", "select", "--noise", "1e308"),
         r"argument --noise: 1e308 .*\[0, 1\]"),
    Case("bound-select-smoothness-inf", argv("calibrate", "select", "--smoothness", "inf"),
         r"argument --smoothness: inf"),
    Case("bound-wizard-reference-distance",
         argv("calibrate", "wizard", "--profile", "sim", "--yes", "--reference-distance-m",
              "1e308"),
         r"argument --reference-distance-m: 1e308 .*<= 100"),
    Case("bound-wizard-noise-nan", argv("calibrate", "wizard", "--profile", "sim", "--yes",
                                        "--noise", "nan"),
         r"argument --noise: nan"),
    Case("bound-import-integration-time",
         argv("calibrate", "import", "TMP/s.csv", "--kind", "light", "--name", "X",
              "--integration-time-ms", "1e308"),
         r"argument --integration-time-ms: 1e308"),
    Case("bound-batch-workers", argv("batch", "TMP", "--workers", "1000000000"),
         r"--workers 1000000000 is out of range .*\[1, 1024\]"),
    Case("bound-basis-components-zero", argv("calibrate", "basis", "--components", "0"),
         r"argument --components: 0 .*\[1, 1000\]"),
    Case("bound-board-measured-square-huge",
         with_file("b.yaml", "board: {squares: [10, 7], square_length_m: 0.026, "
                   "marker_length_m: 0.0195}\n", "board", "--snippet", "TMP/b.yaml",
                   "--measured-square-mm", "1e308"),
         r"measured square length 1e\+305 m is not within \[0\.013, 0\.052\] m"),
    Case("bound-config-solver-iterations", config("optimise: {solver: {max_iterations: "
                                                  "1000000000}}\n"),
         r"solver\.max_iterations' is 1000000000 .*\[0, 10000\]"),
    Case("bound-relight-light-far", argv("relight", "TMP/s", "--view", "0", "--light-pos",
                                         "1e300,0,0"),
         r"--light-pos '1e300,0,0' is too far .*\[-1000, 1000\] m"),
    Case("bound-relight-camera-eye-far",
         with_file("cam.yaml", "width: 64\nheight: 48\nfocal_px: 80\neye: [1.0e+300, 0, 0]\n"
                   "target: [0, 0, 0]\n", "relight", "TMP/s", "--camera", "TMP/cam.yaml"),
         r"cam\.yaml: key 'eye\[0\]' is 1e\+300|cam\.yaml: key 'eye' .*\[-1000, 1000\]"),
    Case("bound-check-chart-view-negative", argv("check-chart", "TMP/s", "--view", "-2"),
         r"argument --view: -2 is not allowed .*\[0, 999\]"),
    Case("bound-camera-fit-white-level-inf",
         argv("calibrate", "camera", "--patches", "TMP/p.csv", "--lamp", "L", "--name", "C",
              "--white-level", "inf"),
         r"argument --white-level: inf"),
    Case("bound-flat-field-aperture",
         argv("calibrate", "flat-field", "--lensfun", "Canon EOS 5D Mark II", "--lens", "L",
              "--focal", "50", "--aperture", "0.01"),
         r"argument --aperture: 0\.01 .*\[0\.5, 256\]"),
    Case("bound-wizard-card-distance",
         argv("calibrate", "wizard", "--profile", "sim", "--yes", "--card-distance-m", "1e308"),
         r"argument --card-distance-m: 1e308 .*<= 100"),
    Case("bound-view-port", argv("view", "TMP", "--port", "70000"),
         r"--port 70000 is not a port number"),
]


# -- messages that suggested an impossible fix --------------------------------------------------
def _store_in_env(value: str) -> Callable[[Path], list[str]]:
    def make(tmp: Path) -> list[str]:
        write(tmp / "afile", "x")
        os.environ["SPECTRAL_RIG_STORE"] = value.replace("TMP", str(tmp))  # restored below
        return ["calibrate", "list"]

    return make


UNCLEAR = [
    Case("unclear-store-not-empty-folder",
         with_file("full/notes.txt", "x", "calibrate", "list", "--store", "TMP/full"),
         r"no calibration store at .*full — create one with `rig calibrate init-store "
         r"NEW_FOLDER`"),
    Case("unclear-store-env-a-file", _store_in_env("TMP/afile"),
         r"\$SPECTRAL_RIG_STORE .*afile is an existing file"),
    Case("unclear-store-env-under-a-file", _store_in_env("TMP/afile/store"),
         r"\$SPECTRAL_RIG_STORE .*afile is a file"),
]

TABLE = TEXT + NUMBERS + UNCLEAR


def _mkdir(path: Path) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    return path


def _store(tmp: Path) -> str:
    from calibration.store import CalibrationStore

    return str(CalibrationStore.create_default(tmp / "store").root)


def snapshot(root: Path) -> dict[str, str]:
    """Every path under ``root``: a file's sha256, 'folder' or a link's target."""
    out = {}
    for path in sorted(root.rglob("*")):
        name = path.relative_to(root).as_posix()
        if path.is_symlink():
            out[name] = "-> " + os.readlink(path)
        elif path.is_dir():
            out[name] = "folder"
        else:
            out[name] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


@pytest.fixture(autouse=True)
def _own_store_and_no_lock_holders(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                   ) -> Iterator[None]:
    monkeypatch.setenv("SPECTRAL_RIG_STORE", str(tmp_path / "default-store"))
    yield
    release_all()


def test_the_table_is_large_enough() -> None:
    assert len(TABLE) >= 45
    assert len({case.id for case in TABLE}) == len(TABLE)


@pytest.mark.parametrize("case", TABLE, ids=[case.id for case in TABLE])
def test_bad_input_is_one_clear_line_and_changes_nothing(
    case: Case, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = case.make(tmp_path)
    before = snapshot(tmp_path)
    code, text = run_cli(args, capsys)
    assert code != 0, text
    assert "internal error" not in text and "Traceback" not in text, text
    errors = [line for line in text.splitlines() if "error:" in line]
    assert len(errors) == 1, text  # one line, whatever the user text holds
    assert re.search(case.expect, errors[0]), text
    assert snapshot(tmp_path) == before


def test_user_text_in_a_session_prints_as_itself(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A session path with markup and a newline, and a note with markup and emoji codes: the
    capture, `session info` and `session verify` succeed and print them as they are, with the
    newline as an escape (they crashed with a MarkupError)."""
    data = yaml.safe_load(SMALL)
    data["plan"]["views"] = 2
    prof = write(tmp_path / "p.yaml", yaml.safe_dump(data))
    session = tmp_path / "a[/x]b\nc:cat:"
    note = "n[/y]\nline2 :smile: [bold]x"
    assert main(["capture", "--profile", str(prof), "--out", str(session), "--yes",
                 "--note", note]) == 0
    out = capsys.readouterr()
    shown = str(session).replace(NL, "\\n")
    assert f"frames in {shown}" in " ".join(out.err.split())  # the terminal may wrap it
    assert out.out == shown + NL
    assert main(["session", "info", str(session)]) == 0
    info = capsys.readouterr().out
    assert f"session       {shown}\n" in info
    assert "notes         n[/y]\\nline2 :smile: [bold]x\n" in info
    assert main(["session", "verify", str(session)]) == 0
    assert capsys.readouterr().out.startswith("ok: ")


def test_a_problem_names_the_view_from_zero(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`session verify` names a frame's view as the manifest and `rig relight --view` do."""
    from core.manifest import read_manifest

    data = yaml.safe_load(SMALL)
    data["plan"]["views"] = 2
    prof = write(tmp_path / "p.yaml", yaml.safe_dump(data))
    session = tmp_path / "s"
    assert main(["capture", "--profile", str(prof), "--out", str(session), "--yes"]) == 0
    record = next(r for r in read_manifest(session) if r.view == 0)
    (session / record.path).write_bytes(b"not the frame")
    capsys.readouterr()
    assert main(["session", "verify", str(session)]) == 1
    line = next(x for x in capsys.readouterr().out.splitlines() if f"frame {record.frame} " in x)
    assert f"(view 0, {record.illumination})" in line


def test_a_log_message_stays_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    """Warnings naming a path print it as itself, a newline as an escape."""
    import logging

    from rig.cli import configure_logging

    configure_logging(0, False)
    logging.getLogger("core.manifest").warning("%s: ignoring the torn last line %d",
                                               "/s[/x]\nb", 3)
    err = capsys.readouterr().err
    assert "/s[/x]\\nb: ignoring the torn last line 3" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize(
    ("raised", "fix"),
    [
        (ValueError("expected non-negative integer"), "check the profile's devices.camera"),
        (OverflowError("timestamp out of range"), "check the profile's devices.camera"),
        (OSError(5, "Input/output error"), "cable/power"),
    ],
)
def test_a_device_failure_suggests_a_fix_that_can_work(raised: Exception, fix: str) -> None:
    """A value no device takes is not blamed on the cable; a failed read or write is."""
    from core.errors import RigError
    from rig.capture.devices import device_errors

    with pytest.raises(RigError) as caught, device_errors("camera", "sim", "open"):
        raise raised
    assert fix in str(caught.value)
    assert ("cable" in str(caught.value)) == (fix == "cable/power")
