"""The bad-input table (issue 17): each row runs the real CLI (`rig.cli.main`) on one bad input
— profiles, reconstruct configs, sessions, `rig board`, `rig relight`, `rig calibrate` output
paths, the command line itself — and expects a non-zero exit, one line naming the file, key or
flag (the `expect` text), and neither an internal error nor a traceback."""

from __future__ import annotations

import re
import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from lockholder import hold, release_all

from rig.cli import build_parser, main

BINARY = bytes(range(256)) * 4
SIM = """\
devices:
  light: {driver: sim}
  camera: {driver: sim}
illuminations:
  LED2: {w: 1.0}
  LED3: {r: 1.0, g: 1.0, b: 1.0}
plan: {views: 4, illuminations: all}
"""


@dataclass(frozen=True)
class Case:
    id: str
    make: Callable[[Path], list[str]]  # builds the inputs under tmp_path, returns argv
    expect: str  # what the message must name (file, key or flag), a regular expression


def write(path: Path, text: str | bytes) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


# -- profiles (`rig capture --profile P`) ------------------------------------------------------
def profile(text: str | bytes, name: str = "p.yaml") -> Callable[[Path], list[str]]:
    def make(tmp: Path) -> list[str]:
        path = write(tmp / name, text)
        return ["capture", "--profile", str(path), "--out", str(tmp / "out"), "--yes"]

    return make


def sim_with(extra: str) -> str:
    return SIM + extra


PROFILES = [
    Case("profile-binary", profile(BINARY), r"p\.yaml.*not UTF-8"),
    Case("profile-radius-fifty", profile(sim_with("sim:\n  trajectory: {radius_m: fifty}\n")),
         r"p\.yaml.*sim\.trajectory\.radius_m"),
    Case("profile-radius-negative", profile(sim_with("sim:\n  trajectory: {radius_m: -1}\n")),
         r"sim\.trajectory\.radius_m"),
    Case("profile-elevation-500",
         profile(SIM.replace("illuminations: all}", "illuminations: all, trajectory: "
                             "{elevations_deg: [20, 500]}}")),
         r"plan\.trajectory\.elevations_deg.*\[-90, 90\]"),
    Case("profile-sim-elevation-500",
         profile(sim_with("sim:\n  trajectory: {elevations_deg: [500]}\n")),
         r"sim\.trajectory\.elevations_deg"),
    Case("profile-elevation-inf",
         profile(SIM.replace("illuminations: all}", "illuminations: all, trajectory: "
                             "{elevations_deg: [.inf]}}")),
         r"plan\.trajectory\.elevations_deg"),
    Case("profile-duplicate-top-key", profile(SIM + "plan: {views: 8}\n"),
         r"p\.yaml.*duplicate key 'plan'.*line"),
    Case("profile-duplicate-nested-key",
         profile(SIM.replace("LED3: {r", "LED2: {c: 1.0}\n  LED3: {r")),
         r"p\.yaml.*duplicate key 'LED2'"),
    Case("profile-duplicate-inline-key",
         profile(SIM.replace("{views: 4,", "{views: 4, views: 6,")), r"duplicate key 'views'"),
    Case("profile-empty", profile(""), r"p\.yaml is empty"),
    Case("profile-a-list", profile("- a\n- b\n"), r"p\.yaml is \['a', 'b'\] .* a mapping"),
    Case("profile-bad-syntax", profile(SIM + "plan: {views: [\n"), r"p\.yaml is not valid YAML"),
    Case("profile-unknown-key", profile(SIM + "plna: 1\n"), r"p\.yaml.*'plna'"),
    Case("profile-views-zero", profile(SIM.replace("views: 4", "views: 0")), r"plan\.views"),
    Case("profile-views-word", profile(SIM.replace("views: 4", "views: ten")), r"plan\.views"),
    Case("profile-views-negative", profile(SIM.replace("views: 4", "views: -3")), r"plan\.views"),
    Case("profile-level-above-one", profile(SIM.replace("{w: 1.0}", "{w: 2.0}")),
         r"illuminations\.LED2\.w"),
    Case("profile-level-word", profile(SIM.replace("{w: 1.0}", "{w: high}")),
         r"illuminations\.LED2\.w"),
    Case("profile-reserved-illumination", profile(SIM.replace("LED2:", "ambient:")),
         r"illuminations\.ambient"),
    Case("profile-undefined-illumination",
         profile(SIM.replace("illuminations: all}", "illuminations: [LED9]}")),
         r"plan\.illuminations.*LED9"),
    Case("profile-no-camera", profile(SIM.replace("  camera: {driver: sim}\n", "")),
         r"devices\.camera"),
    Case("profile-unknown-driver", profile(SIM.replace("light: {driver: sim}",
                                                       "light: {driver: nosuch}")),
         r"devices\.light\.driver"),
    Case("profile-mount-type", profile(sim_with("light_mount: {type: ceiling}\n")),
         r"light_mount\.type"),
    Case("profile-mount-offset-short", profile(sim_with("light_mount: {offset_m: [1, 2]}\n")),
         r"light_mount\.offset_m"),
    Case("profile-exposure-negative", profile(sim_with("camera_settings: {exposure_s: -1}\n")),
         r"camera_settings\.exposure_s"),
    Case("profile-iso-nan", profile(sim_with("camera_settings: {iso: .nan}\n")),
         r"camera_settings\.iso"),
    Case("profile-settle-negative", profile(SIM.replace("{views: 4,", "{views: 4, settle_s: -1,")),
         r"plan\.settle_s"),
    Case("profile-distance-factor-zero",
         profile(SIM.replace("illuminations: all}", "illuminations: all, trajectory: "
                             "{distance_factors: [0, 1]}}")),
         r"plan\.trajectory\.distance_factors"),
    Case("profile-sim-distances-negative",
         profile(sim_with("sim:\n  trajectory: {distances_m: [-0.5]}\n")),
         r"sim\.trajectory\.distances_m"),
    Case("profile-sim-target-short", profile(sim_with("sim:\n  trajectory: {target_m: [0, 0]}\n")),
         r"sim\.trajectory\.target_m"),
    Case("profile-poses-mode", profile(sim_with("poses: guess\n")), r"'poses'"),
    Case("profile-camera-pair-view",
         profile(sim_with("known_distances:\n  camera_pairs: [{views: [0, 9], metres: 0.1}]\n")),
         r"known_distances\.camera_pairs\[0\]\.views"),
    Case("profile-missing-file", lambda tmp: ["capture", "--profile", str(tmp / "none.yaml"),
                                              "--out", str(tmp / "o"), "--yes"],
         r"none\.yaml does not exist"),
    Case("profile-markup-in-path", profile(BINARY, name="a[/x][gphoto2].yaml"),
         r"a\[/x\]\[gphoto2\]\.yaml"),
]


# -- reconstruct configs (`rig reconstruct S --config C`): checked before any stage runs ------
def config(text: str | bytes) -> Callable[[Path], list[str]]:
    def make(tmp: Path) -> list[str]:
        write(tmp / "s" / "session.yaml", "rig: sim\n")
        path = write(tmp / "c.yaml", text)
        return ["reconstruct", str(tmp / "s"), "--config", str(path)]

    return make


CONFIGS = [
    Case("config-gamma-word", config('optimise: {gamma: "abc"}\n'), r"c\.yaml.*gamma"),
    Case("config-gamma-two", config("optimise: {gamma: [1, 2]}\n"), r"c\.yaml.*gamma"),
    Case("config-gamma-negative", config("optimise: {gamma: [1, -2, 0]}\n"), r"gamma"),
    Case("config-outer-negative", config("optimise: {outer_iterations: -1}\n"),
         r"c\.yaml.*outer_iterations"),
    Case("config-joint-fraction", config("optimise: {joint_iterations: 2.5}\n"),
         r"joint_iterations"),
    Case("config-light-word", config("optimise: {light_iterations: ten}\n"), r"light_iterations"),
    Case("config-solver-negative", config("optimise: {solver: {max_iterations: -5}}\n"),
         r"solver.*max_iterations"),
    Case("config-solver-not-mapping", config("optimise: {solver: 3}\n"), r"solver"),
    Case("config-light-mode", config("optimise: {light_mode: wobbly}\n"), r"light_mode"),
    Case("config-robust-scale-nan", config("optimise: {robust_scale: .nan}\n"), r"robust_scale"),
    Case("config-bool-word", config("optimise: {optimise_positions: maybe}\n"),
         r"optimise_positions"),
    Case("config-optimise-list", config("optimise: [1, 2]\n"),
         r"c\.yaml: key 'optimise' is \[1, 2\] .* a mapping"),
    Case("config-duplicate-section", config("optimise: {}\noptimise: {gamma: [1, 1, 1]}\n"),
         r"c\.yaml.*duplicate key 'optimise'"),
    Case("config-duplicate-key", config("optimise:\n  gamma: [1, 1, 1]\n  gamma: [2, 2, 2]\n"),
         r"duplicate key 'gamma'"),
    Case("config-unknown-section", config("optimize: {}\n"), r"c\.yaml.*optimize"),
    Case("config-unknown-key", config("optimise: {gama: [1, 1, 1]}\n"), r"gama"),
    Case("config-patchmatch-word", config("mesh: {patchmatch: {scale: half}}\n"),
         r"c\.yaml.*mesh\.patchmatch.*scale"),
    Case("config-patchmatch-unknown", config("mesh: {patchmatch: {scael: 0.5}}\n"),
         r"mesh\.patchmatch.*scael"),
    Case("config-stereo-word", config("mesh: {stereo: {window: seven}}\n"),
         r"mesh\.stereo.*window"),
    Case("config-binary", config(BINARY), r"c\.yaml.*not UTF-8"),
    Case("config-a-list", config("- 1\n"), r"c\.yaml is not a mapping"),
    Case("config-missing", lambda tmp: ["reconstruct", str(tmp), "--config",
                                        str(tmp / "none.yaml")], r"none\.yaml does not exist"),
    Case("config-a-folder", lambda tmp: ["reconstruct", str(tmp), "--config", str(tmp)],
         r"is a folder"),
    Case("config-max-faces-word", config("subdivide: {max_faces: many}\n"),
         r"subdivide.*max_faces"),
    Case("config-demosaic", config("decode: {demosaic: magic}\n"), r"decode\.demosaic"),
    Case("config-saturation-word", config("decode: {saturation: high}\n"), r"decode.*saturation"),
    Case("config-voxels-fraction", config("mesh: {voxels: 12.5}\n"), r"mesh.*voxels"),
    Case("config-section-scalar", config("visibility: 5\n"), r"visibility"),
    Case("config-stereo-unknown", config("mesh: {stereo: {nosuch: 1}}\n"), r"c\.yaml.*nosuch"),
    Case("config-detail-word", config("resolution: {detail: huge}\n"),
         r"c\.yaml.*resolution\.detail.*draft"),
    Case("config-edge-negative", config("resolution: {edge_mm: -1}\n"),
         r"c\.yaml.*resolution\.edge_mm"),
]


# -- sessions (`rig reconstruct S`) -------------------------------------------------------------
SESSIONS = [
    Case("session-missing", lambda tmp: ["reconstruct", str(tmp / "nowhere")],
         r"nowhere is not a session directory"),
    Case("session-a-file", lambda tmp: ["reconstruct", str(write(tmp / "f", "x"))],
         r"f is not a session directory"),
    Case("session-yaml-duplicate",
         lambda tmp: ["reconstruct", str(write(tmp / "s" / "session.yaml",
                                                "rig: sim\nrig: real\n").parent)],
         r"session\.yaml.*duplicate key 'rig'"),
    Case("session-yaml-binary",
         lambda tmp: ["reconstruct", str(write(tmp / "s" / "session.yaml", BINARY).parent)],
         r"session\.yaml.*not"),
    Case("session-initial-mesh-missing",
         lambda tmp: ["reconstruct", str(write(tmp / "s" / "session.yaml", "rig: sim\n").parent),
                      "--initial-mesh", str(tmp / "none.ply")],
         r"none\.ply"),
]


def held_session(tmp: Path) -> list[str]:
    session = write(tmp / "s" / "session.yaml", "format: 1\n").parent
    hold(session, "rig capture")
    return ["reconstruct", str(session)]


def session_with_lock_folder(tmp: Path) -> list[str]:
    session = write(tmp / "s" / "session.yaml", "format: 1\n").parent
    (session / ".lock").mkdir()
    return ["reconstruct", str(session)]


SESSIONS += [
    Case("session-in-use", held_session,
         r"s is in use by `rig capture` \(PID \d+ on .+, since \S+Z\) — wait for it to finish"),
    Case("session-lock-a-folder", session_with_lock_folder,
         r"cannot open the lock file .*s/\.lock .*remove"),
]


# -- rig board -----------------------------------------------------------------------------------
def board(*args: str) -> Callable[[Path], list[str]]:
    def make(tmp: Path) -> list[str]:
        (tmp / "adir").mkdir(exist_ok=True)
        write(tmp / "afile.pdf", "x")
        write(tmp / "dup.yaml", "board:\n  squares: [7, 5]\n  squares: [8, 6]\n")
        write(tmp / "bin.yaml", BINARY)
        return ["board", *(a.replace("TMP", str(tmp)) for a in args)]

    return make


BOARD = [
    Case("board-squares-0x-3", board("--squares", "0x-3", "--out", "TMP/b.pdf"), r"--squares"),
    Case("board-squares-one-number", board("--squares", "7", "--out", "TMP/b.pdf"), r"--squares"),
    Case("board-squares-words", board("--squares", "axb", "--out", "TMP/b.pdf"), r"--squares"),
    Case("board-squares-1x5", board("--squares", "1x5", "--out", "TMP/b.pdf"), r"--squares"),
    Case("board-out-a-folder", board("--out", "TMP/adir"), r"--out .*adir is a folder"),
    Case("board-out-under-a-file", board("--out", "TMP/afile.pdf/b.pdf"),
         r"--out .*afile\.pdf is a file"),
    Case("board-out-txt", board("--out", "TMP/b.txt"), r"b\.txt"),
    Case("board-dpi-negative", board("--out", "TMP/b.png", "--dpi", "-5"), r"--dpi"),
    Case("board-square-negative", board("--out", "TMP/b.pdf", "--square-mm", "-3"), r"squares"),
    Case("board-marker-ratio", board("--out", "TMP/b.pdf", "--marker-ratio", "2"),
         r"marker ratio"),
    Case("board-dictionary", board("--out", "TMP/b.pdf", "--dictionary", "FOO"), r"FOO"),
    Case("board-measured-nan", board("--out", "TMP/b.pdf", "--measured-square-mm", "nan"),
         r"measured square"),
    Case("board-snippet-missing", board("--snippet", "TMP/none.yaml", "--measured-square-mm", "30"),
         r"none\.yaml does not exist"),
    Case("board-snippet-duplicate",
         board("--snippet", "TMP/dup.yaml", "--measured-square-mm", "30"),
         r"dup\.yaml.*duplicate key 'squares'"),
    Case("board-snippet-binary", board("--snippet", "TMP/bin.yaml", "--measured-square-mm", "30"),
         r"bin\.yaml"),
    Case("board-snippet-a-folder", board("--snippet", "TMP/adir", "--measured-square-mm", "30"),
         r"--snippet .*adir is a folder"),
    Case("board-nothing-to-do", board(), r"--out"),
]


# -- rig relight: every argument is checked before the reconstruction is read -------------------
def relight(*args: str) -> Callable[[Path], list[str]]:
    def make(tmp: Path) -> list[str]:
        (tmp / "adir").mkdir(exist_ok=True)
        write(tmp / "cam.yaml", "width: 64\nheight: 48\nwidth: 32\n")
        write(tmp / "bin.yaml", BINARY)
        write(tmp / "far.yaml", "width: 64\nheight: 48\nfocal_px: long\neye: [1, 0, 0]\n"
              "target: [0, 0, 0]\n")
        return ["relight", str(tmp / "s"), *(a.replace("TMP", str(tmp)) for a in args)]

    return make


RELIGHT = [
    Case("relight-light-pos-nan", relight("--view", "0", "--light-pos", "nan,0,0"),
         r"--light-pos 'nan,0,0' is not finite"),
    Case("relight-light-pos-inf", relight("--view", "0", "--light-pos", "0,inf,0"),
         r"--light-pos"),
    Case("relight-light-pos-two", relight("--view", "0", "--light-pos", "1,2"), r"--light-pos"),
    Case("relight-light-pos-words", relight("--view", "0", "--light-pos", "a,b,c"),
         r"--light-pos"),
    Case("relight-exposure-negative", relight("--view", "0", "--exposure", "-1"), r"--exposure"),
    Case("relight-out-a-folder", relight("--view", "0", "--out", "TMP/adir"),
         r"--out .*adir is a folder"),
    Case("relight-camera-duplicate", relight("--camera", "TMP/cam.yaml"),
         r"cam\.yaml.*duplicate key 'width'"),
    Case("relight-camera-binary", relight("--camera", "TMP/bin.yaml"), r"bin\.yaml"),
    Case("relight-camera-focal-word", relight("--camera", "TMP/far.yaml"),
         r"far\.yaml: key 'focal_px' is 'long'"),
    Case("relight-no-recon", relight("--view", "0"), r"reflectance\.npz"),
    Case("relight-no-view-or-camera", relight(), r"--view"),
]


# -- rig calibrate output paths and store ------------------------------------------------------
def calibrate(*args: str) -> Callable[[Path], list[str]]:
    def make(tmp: Path) -> list[str]:
        (tmp / "adir").mkdir(exist_ok=True)
        write(tmp / "afile", "x")
        write(tmp / "dupstore" / "index.yaml", "format: x\nformat: y\n")
        return ["calibrate", *(a.replace("TMP", str(tmp)) for a in args)]

    return make


CALIBRATE = [
    Case("calibrate-store-a-file", calibrate("list", "--store", "TMP/afile"),
         r"--store .*afile is an existing file"),
    Case("calibrate-store-duplicate", calibrate("list", "--store", "TMP/dupstore"),
         r"index\.yaml.*duplicate key 'format'"),
    Case("calibrate-basis-out-under-file", calibrate("basis", "--out", "TMP/afile/b.npz"),
         r"--out .*afile is a file"),
    Case("calibrate-basis-plot-folder", calibrate("basis", "--plot", "TMP/adir"),
         r"--plot .*adir is a folder"),
    Case("calibrate-select-plot-folder", calibrate("select", "--plot", "TMP/adir"),
         r"--plot .*adir is a folder"),
    Case("calibrate-init-store-a-file", calibrate("init-store", "TMP/afile"), r"afile"),
    Case("calibrate-import-binary",
         lambda tmp: ["calibrate", "import", str(write(tmp / "s.txt", BINARY)), "--kind", "light",
                      "--name", "X", "--store", str(tmp / "st")],
         r"s\.txt is a binary file"),
    Case("calibrate-import-word",
         lambda tmp: ["calibrate", "import", str(write(tmp / "s.csv", "wavelength_nm,power\n400,"
                                                       "abc\n")), "--kind", "light", "--name",
                      "X", "--store", str(tmp / "st")],
         r"s\.csv:2: not a number"),
    Case("calibrate-import-too-short",
         lambda tmp: ["calibrate", "import", str(write(tmp / "s.csv", "wavelength_nm,power\n400,1"
                                                       "\n410,2\n")), "--kind", "light", "--name",
                      "X", "--store", str(tmp / "st")],
         r"s\.csv: only 2 samples"),
    Case("calibrate-import-missing",
         lambda tmp: ["calibrate", "import", str(tmp / "none.csv"), "--kind", "light", "--name",
                      "X", "--store", str(tmp / "st")],
         r"none\.csv does not exist"),
]


# -- the command line ----------------------------------------------------------------------------
COMMAND_LINE = [
    Case("cli-unknown-command", lambda tmp: ["reconstrct", str(tmp)], r"reconstrct"),
    Case("cli-unknown-flag", lambda tmp: ["reconstruct", str(tmp), "--fast"], r"--fast"),
    Case("cli-detail-word", lambda tmp: ["reconstruct", str(tmp), "--detail", "ultra"],
         r"--detail.*ultra.*draft"),
    Case("cli-edge-zero", lambda tmp: ["reconstruct", str(tmp), "--edge-mm", "0"],
         r"--edge-mm.*0"),
    Case("capture-out-a-file",
         lambda tmp: ["capture", "--profile", "sim", "--out", str(write(tmp / "f", "x")), "--yes"],
         r"--out .*f is an existing file"),
    Case("capture-out-under-a-file",
         lambda tmp: ["capture", "--profile", "sim", "--out", str(write(tmp / "f", "x") / "s"),
                      "--yes"],
         r"--out .*f is a file"),
    Case("cli-demo-out-a-file", lambda tmp: ["demo", "--out", str(write(tmp / "f", "x"))],
         r"--out .*f is an existing file"),
]

EVALUATE = [
    Case("evaluate-no-recon",
         lambda tmp: ["evaluate", str(tmp / "nowhere"), "--gt-mesh", str(tmp / "m.ply"),
                      "--gt-reflectance", str(tmp / "r.npy")],
         r"nowhere"),
]

TABLE = PROFILES + CONFIGS + SESSIONS + BOARD + RELIGHT + CALIBRATE + EVALUATE + COMMAND_LINE


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse's own errors
        code = int(exit_.code or 0)
    out = capsys.readouterr()
    return code, out.out + out.err


@pytest.fixture(autouse=True)
def _end_lock_holders() -> Iterator[None]:
    yield
    release_all()


def test_the_table_is_large_enough() -> None:
    assert len(TABLE) >= 60
    assert len({case.id for case in TABLE}) == len(TABLE)


@pytest.mark.parametrize("case", TABLE, ids=[case.id for case in TABLE])
def test_bad_input_is_one_clear_line(
    case: Case, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, text = run_cli(case.make(tmp_path), capsys)
    assert code != 0, text
    assert "internal error" not in text and "Traceback" not in text, text
    errors = [line for line in text.splitlines() if "error:" in line]
    assert len(errors) == 1, text  # one line, not a usage block or a wrapped message
    assert re.search(case.expect, errors[0]), text


def test_errors_print_brackets_literally(capsys: pytest.CaptureFixture[str]) -> None:
    """Rich markup is off for messages: `[/x]` does not crash, `[gphoto2]` is not eaten."""
    from core.errors import RigError
    from rig import cli

    def fail(_: object) -> int:
        raise RigError("closing tag [/x] here", "pip install 'spectral-rig[gphoto2]'")

    parser = build_parser()
    args = parser.parse_args(["devices"])
    args.func = fail
    original = cli.build_parser

    class Parser:
        def parse_args(self, argv: object) -> object:
            return args

    cli.build_parser = lambda: Parser()  # type: ignore[assignment,return-value]
    try:
        code, text = run_cli([], capsys)
    finally:
        cli.build_parser = original
    assert code == 2
    assert "closing tag [/x] here — pip install 'spectral-rig[gphoto2]'" in text


@pytest.mark.slow
def test_a_corrupt_raw_frame_is_skipped_with_a_non_zero_exit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """decode.on_bad_frame: skip (the default) reconstructs without the frame, names it and
    exits 3; with `stop` the run refuses with one error line naming it."""
    import sys

    sys.path.insert(0, str(Path(__file__).parents[1] / "reconstruct" / "run"))
    from recon_tiny import make_session, reconstruct_args

    session, conf = make_session(tmp_path)
    capsys.readouterr()
    raw = sorted((session / "raw").rglob("*.dng"))[3]
    raw.write_bytes(raw.read_bytes()[:4000])  # truncated after capture
    name = raw.relative_to(session).as_posix()
    code, text = run_cli(reconstruct_args(session, conf), capsys)
    assert code == 3, text
    assert name in text and "unusable" in text and "Traceback" not in text
    shutil.rmtree(session / "recon")
    conf.write_text(conf.read_text() + "decode: {on_bad_frame: stop}\n")
    code, text = run_cli(reconstruct_args(session, conf), capsys)
    assert code == 2 and name in text and "internal error" not in text, text
