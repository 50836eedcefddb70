"""Capture-rig overhead: a sim capture (views × illuminations) with a zero-latency camera that
writes a pre-made valid DNG instantly, so only the rig's own work per frame is measured (light
switching, decode check, fsync, rename, sha256, manifest append, progress, and the board and
exposure checks; the DNG is a sim render of the object on its board, or with ``--template
noise`` a noise frame in which no board is ever found); and the resume time
after a SIGKILL mid-capture (a subprocess capture is killed, ``--resume`` is timed until the
next frame lands in the manifest), once with the zero-latency camera and once through the real
``rig capture`` CLI with the rendering sim camera.

    python -m bench.capture                # 40 views x 3 illuminations, 640x480 frames
    python -m bench.capture --quick        # smoke size
    python -m bench.capture --width 5616 --height 3744 --views 4   # a 21 MP camera's files
"""

from __future__ import annotations

import argparse
import io
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from rich.console import Console

from bench._common import (
    DEFAULT_OUT,
    REPO,
    ResultTable,
    emit_worker_result,
    machine_info,
    make_console,
    peak_rss_mb,
    report,
)

TARGET_MS = 50.0


# --- the zero-latency camera -------------------------------------------------------------


def render_template(path: Path, profile: Path, seed: int = 0) -> Path:
    """The sim camera's DNG of the profile's first view under its first illumination (the
    object on its board), rendered once and moved to ``path``."""
    from rig.capture.devices import open_devices
    from rig.profile import load_profile

    loaded = load_profile(profile)
    devices = open_devices(loaded, seed, None)
    try:
        devices.goto_view(0)
        assert devices.light is not None
        devices.light.set_levels(next(iter(loaded.illuminations.values())))
        frame = devices.camera.capture(path.parent / "render", "template")
    finally:
        devices.close()
    shutil.move(Path(frame.paths[0]), path)
    return path


def make_template(path: Path, width: int, height: int, seed: int = 0) -> Path:
    """A valid 14-bit RGGB DNG of ``width × height`` (noise around mid-grey), written once."""
    from drivers.sim.dng import write_dng

    rng = np.random.default_rng(seed)
    mosaic = rng.integers(2000, 9000, size=(height, width), dtype=np.uint16)
    write_dng(
        path,
        mosaic,
        black_level=512,
        white_level=16383,
        exposure_s=0.8,
        iso=400,
        make="spectral-rig",
        model="ZeroLatencyCam",
        serial="BENCH-0001",
        color_matrix=np.eye(3),
        as_shot_neutral=np.ones(3),
    )
    return path


class ZeroLatencyCamera:
    """A :class:`drivers.protocols.Camera` that writes the template's bytes at once; it times
    its own writes so they can be taken out of the rig's overhead."""

    def __init__(self, template: Path) -> None:
        self.data = Path(template).read_bytes()
        self.seconds: list[float] = []

    def describe(self) -> dict[str, Any]:
        return {"kind": "camera", "model": "zero-latency bench camera", "transport": "none"}

    def capture(self, out_dir: Path, stem: str) -> Any:
        import datetime as dt

        from drivers.protocols import CapturedFrame

        t0 = time.perf_counter()
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"{stem}.dng"
        path.write_bytes(self.data)
        self.seconds.append(time.perf_counter() - t0)
        return CapturedFrame(
            paths=(path,),
            exposure_s=0.8,
            iso=400.0,
            camera_serial="BENCH-0001",
            timestamp=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
            extra={},
        )

    def close(self) -> None:
        return None


def zero_latency_rig(camera: ZeroLatencyCamera) -> Callable[..., Any]:
    """``open_rig`` for run_capture: the profile's devices with the camera swapped."""
    from rig.capture.devices import open_devices

    def factory(profile: Any, seed: int, ask: Any) -> Any:
        devices = open_devices(profile, seed, ask)
        devices.camera.close()
        devices.camera = camera
        devices.names["camera"] = "zero-latency"
        return devices

    return factory


def write_profile(path: Path, views: int, illuminations: int, width: int, height: int) -> Path:
    """The shipped sim profile with the benchmark's plan (views, first N illuminations)."""
    from rig.profile import resolve_profile

    data = yaml.safe_load(resolve_profile("sim").read_text())
    names = list(data["illuminations"])[:illuminations]
    data["illuminations"] = {k: data["illuminations"][k] for k in names}
    data["plan"]["views"] = views
    data["plan"]["illuminations"] = "all"
    data["sim"] = {
        **dict(data.get("sim") or {}),
        "subdivisions": 4,  # the zero-latency camera never renders; keep the sim setup small
        # the same field of view at every size (the sim's default: 800 px focal at 640 wide)
        "camera": {"width": width, "height": height, "focal_px": 800.0 * width / 640},
    }
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


# --- measurements -------------------------------------------------------------------------


def per_frame_overhead(profile: Path, template: Path, session: Path) -> dict[str, Any]:
    """In-process capture; per-frame time between manifest appends minus the camera's write."""
    from rig.capture import run_capture
    from rig.capture.board_check import board_binnings
    from rig.capture.frames import read_raw

    camera = ZeroLatencyCamera(template)
    stamps: list[float] = []
    t0 = time.perf_counter()
    run_capture(
        profile,
        session,
        yes=True,
        console=Console(file=io.StringIO()),
        open_rig=zero_latency_rig(camera),
        on_frame=lambda _record: stamps.append(time.perf_counter()),
    )
    total = time.perf_counter() - t0
    from core.session import Session

    boards = list(Session.open(session).info.board_checks.values())
    intervals = np.diff(stamps)  # the first frame's time is the setup, reported apart
    cam = np.asarray(camera.seconds[1:])
    overhead_ms = (intervals - cam[: len(intervals)]) * 1e3
    return {
        "frames": len(stamps),
        "total_s": total,
        "setup_s": stamps[0] - t0,
        "overhead_ms": overhead_ms.tolist(),
        "camera_write_ms_mean": float(np.mean(camera.seconds) * 1e3),
        "board_checks": [{"corners": b["corners"], "binning": b["binning"]} for b in boards],
        "board_quick_binning": board_binnings(read_raw(template))[0],
    }


def component_times(template: Path, profile: Path, work: Path, repeats: int) -> dict[str, float]:
    """Median ms of the steps store_frame does per frame, each on its own, and of the checks
    (board: a view's first lit frame; exposure: each illumination's first frame)."""
    from core.files import fsync_dir, sha256_file
    from core.manifest import FrameRecord, append_manifest
    from rig.capture.board_check import look_for_board
    from rig.capture.engine import BOARD_MIN_CORNERS
    from rig.capture.frames import check_exposure, read_raw
    from rig.profile import load_profile

    work.mkdir(parents=True, exist_ok=True)
    data = template.read_bytes()
    target = work / "frame.dng"
    target.write_bytes(data)
    record = FrameRecord(0, 0, "LED1", "raw/x.dng", "0" * 64, 0.8, 400.0, "t", {})

    def timed(fn: Callable[[], object]) -> float:
        samples = []
        for _ in range(repeats):
            t = time.perf_counter()
            fn()
            samples.append(time.perf_counter() - t)
        return statistics.median(samples) * 1e3

    def fsync_file() -> None:
        with open(target, "rb+") as handle:
            os.fsync(handle.fileno())

    def write_fsync() -> None:
        target.write_bytes(data)
        fsync_file()

    board = load_profile(profile).board
    assert board is not None
    raw = read_raw(target)
    return {
        "decode check (rawpy)": timed(lambda: read_raw(target)),
        "sha256": timed(lambda: sha256_file(target)),
        "write + fsync file": timed(write_fsync),
        "fsync dir": timed(lambda: fsync_dir(work)),
        "manifest append + fsync": timed(lambda: append_manifest(work, record)),
        "board check, once per view": timed(lambda: look_for_board(raw, board, BOARD_MIN_CORNERS)),
        "exposure check, once per illumination": timed(lambda: check_exposure(raw, "LED1", 0.8)),
    }


def _manifest_count(session: Path) -> int:
    path = session / "manifest.jsonl"
    try:
        return path.read_bytes().count(b"\n")
    except OSError:
        return 0


def _wait_for(
    proc: subprocess.Popen[bytes], session: Path, count: int, timeout_s: float
) -> float | None:
    """Poll the manifest until it holds ``count`` lines; the time it happened (perf_counter)."""
    end = time.perf_counter() + timeout_s
    while time.perf_counter() < end:
        if _manifest_count(session) >= count:
            return time.perf_counter()
        if proc.poll() is not None:
            return time.perf_counter() if _manifest_count(session) >= count else None
        time.sleep(0.002)
    return None


def kill_and_resume(
    label: str,
    start_cmd: list[str],
    resume_cmd: list[str],
    session: Path,
    total: int,
    kill_at: int,
    finish: bool,
    timeout_s: float,
    events_flag: bool,
) -> dict[str, Any]:
    """SIGKILL a capture once ``kill_at`` frames are in the manifest, then time ``resume_cmd``
    from launch until the next frame is in the manifest; check the finished session."""
    from core.manifest import read_manifest, verify_frames

    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "cwd": REPO}
    proc = subprocess.Popen(start_cmd, **quiet)  # type: ignore[call-overload]
    if _wait_for(proc, session, kill_at, timeout_s) is None:
        proc.kill()
        raise RuntimeError(f"{label}: the capture never reached {kill_at} frames")
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    at_kill = _manifest_count(session)
    events = session.parent / f"{session.name}.events.json"
    events.unlink(missing_ok=True)
    if events_flag:
        resume_cmd = [*resume_cmd, "--events", str(events)]
    t0, wall0 = time.perf_counter(), time.time()
    resumed = subprocess.Popen(resume_cmd, **quiet)  # type: ignore[call-overload]
    t_next = _wait_for(resumed, session, at_kill + 1, timeout_s)
    complete = None
    if finish:
        resumed.wait(timeout=timeout_s)
        records = read_manifest(session)
        frames = [r.frame for r in records]
        complete = (
            len(frames) == total
            and len(set(frames)) == total
            and not verify_frames(session, records)
        )
    else:
        resumed.send_signal(signal.SIGKILL)
        resumed.wait()
    stamps = json.loads(events.read_text()) if events.is_file() else {}
    return {
        "label": label,
        "frames_at_kill": at_kill,
        "interpreter_and_imports_s": stamps["imported"] - wall0 if stamps else None,
        # until the manifest line (the worker's on_frame comes later, after the exposure check)
        "resume_in_process_s": t_next - t0 - (stamps["imported"] - wall0)
        if stamps and t_next is not None
        else None,
        "resume_to_next_frame_s": None if t_next is None else t_next - t0,
        "complete_and_verified": complete,
    }


def _seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f} s"


def _python(*args: str) -> list[str]:
    return [sys.executable, "-m", *args]


# --- main ---------------------------------------------------------------------------------


def worker(argv: list[str]) -> int:
    """``--worker``: one capture (or resume) with the zero-latency camera, for kill tests."""
    p = argparse.ArgumentParser()
    p.add_argument("--profile", type=Path, required=True)
    p.add_argument("--session", type=Path, required=True)
    p.add_argument("--template", type=Path, required=True)
    p.add_argument("--resume", action="store_true")
    p.add_argument("--events", type=Path, help="write wall-clock stamps here (JSON)")
    a = p.parse_args(argv)
    from rig.capture import run_capture

    if a.events:  # the interpreter has started and imported the rig
        a.events.write_text(json.dumps({"imported": time.time()}))
    run_capture(
        None if a.resume else a.profile,
        a.session,
        yes=True,
        resume=a.resume,
        console=Console(file=io.StringIO()),
        open_rig=zero_latency_rig(ZeroLatencyCamera(a.template)),
    )
    emit_worker_result({"session": str(a.session)})
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker(argv[1:])
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--views", type=int, default=40)
    parser.add_argument("--illuminations", type=int, default=3, help="first N of the profile's")
    parser.add_argument("--width", type=int, default=640, help="frame width (pixels)")
    parser.add_argument("--height", type=int, default=480, help="frame height (pixels)")
    parser.add_argument("--kill-at", type=float, default=0.5, help="share of frames before kill")
    parser.add_argument("--repeats", type=int, default=20, help="repeats of each component")
    parser.add_argument("--no-cli", action="store_true", help="skip the rig CLI resume test")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--keep", action="store_true", help="keep the session directories")
    parser.add_argument("--quick", action="store_true", help="smoke size (4 views, 2 lights)")
    parser.add_argument(
        "--template",
        choices=("sim", "noise"),
        default="sim",
        help="the camera's frame: a sim render of the object on its board, or noise (no board)",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.views, args.illuminations, args.repeats = 4, 2, 3
        args.width, args.height = 64, 48
    info = machine_info()
    console = make_console()
    work = args.out / "capture_work"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    profile = write_profile(
        work / "profile.yaml", args.views, args.illuminations, args.width, args.height
    )
    template = (
        render_template(work / "template.dng", profile, args.seed)
        if args.template == "sim"
        else make_template(work / "template.dng", args.width, args.height, args.seed)
    )
    total = args.views * args.illuminations
    console.print(f"capture: {args.views} views × {args.illuminations} illuminations = {total}")

    run = per_frame_overhead(profile, template, work / "inprocess")
    parts = component_times(template, profile, work / "components", args.repeats)
    ov = np.asarray(run["overhead_ms"])
    size_mb = template.stat().st_size / 1e6
    t1 = ResultTable(
        f"Rig overhead per frame, zero-latency camera ({args.views} views × "
        f"{args.illuminations} illuminations, {args.width}×{args.height} DNG, {size_mb:.2f} MB, "
        f"{'sim render' if args.template == 'sim' else 'noise, no board'})",
        ["quantity", "value", "target"],
    )
    t1.add("overhead per frame, mean", f"{ov.mean():.1f} ms", f"≤ {TARGET_MS:.0f} ms")
    t1.add("overhead per frame, median", f"{np.median(ov):.1f} ms", "")
    t1.add("overhead per frame, p95", f"{np.percentile(ov, 95):.1f} ms", "")
    t1.add("overhead per frame, max", f"{ov.max():.1f} ms", "")
    t1.add("met", bool(ov.mean() <= TARGET_MS), "")
    t1.add("session setup until first frame", f"{run['setup_s']:.2f} s", "")
    t1.add("whole capture", f"{run['total_s']:.2f} s", "")
    boards = run["board_checks"]
    quick = sum(b["binning"] == run["board_quick_binning"] for b in boards)
    t1.add(
        "board checks: views with ≥ 6 corners; found in the quick look",
        f"{sum(b['corners'] >= 6 for b in boards)}/{len(boards)}; {quick}/{len(boards)}",
        "",
    )
    t1.add("camera write (excluded)", f"{run['camera_write_ms_mean']:.2f} ms", "")
    for name, ms in parts.items():
        if name.startswith(("board check", "exposure check")):
            t1.add(name, f"{ms:.2f} ms", "")
        else:
            t1.add(f"  of which {name}", f"{ms:.2f} ms", "")

    t2 = ResultTable(
        "Resume after SIGKILL mid-capture",
        [
            "capture",
            "killed after",
            "resume → next frame",
            "of which interpreter + imports",
            "of which resume check + devices + frame",
            "complete, hashes OK",
        ],
    )
    kill_at = max(1, int(args.kill_at * total))
    results = []
    session = work / "killed"
    common = ["--profile", str(profile), "--template", str(template), "--session", str(session)]
    results.append(
        kill_and_resume(
            "zero-latency camera (run_capture)",
            _python("bench.capture", "--worker", *common),
            _python("bench.capture", "--worker", *common, "--resume"),
            session,
            total,
            kill_at,
            finish=True,
            timeout_s=600,
            events_flag=True,
        )
    )
    if not args.no_cli:
        cli_session = work / "killed_cli"
        results.append(
            kill_and_resume(
                "`rig capture` CLI, sim camera renders",
                _python(
                    "rig.cli",
                    "capture",
                    "--profile",
                    str(profile),
                    "--out",
                    str(cli_session),
                    "--yes",
                ),
                _python("rig.cli", "capture", "--resume", str(cli_session), "--yes"),
                cli_session,
                total,
                min(kill_at, 3),
                finish=False,
                timeout_s=600,
                events_flag=False,
            )
        )
    for r in results:
        t = r["resume_to_next_frame_s"]
        t2.add(
            r["label"],
            f"{r['frames_at_kill']}/{total}",
            _seconds(t),
            _seconds(r["interpreter_and_imports_s"]),
            _seconds(r["resume_in_process_s"]),
            r["complete_and_verified"],
        )
    payload = {
        "args": {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
        "in_process": run,
        "components_ms": parts,
        "resume": results,
        "bench_peak_rss_mb": peak_rss_mb(),
    }
    notes = [
        "overhead = time between consecutive manifest appends minus the camera's own file write; "
        "it includes moving the sim plate, switching the sim light, the decode check, fsyncs, "
        "rename, sha256, the manifest append, the progress bar, and the board check (each "
        "view's first lit frame) and exposure check (each illumination's first frame)",
        "resume → next frame: from launching the resume process (interpreter start and imports "
        "included) until the manifest holds one more frame; the CLI row includes one sim render",
    ]
    report("capture", args.out, [t1, t2], payload, info, console, notes)
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
