"""`rig session`: verify (re-hash every frame) and summarise a capture session."""

from __future__ import annotations

import argparse
import datetime as dt
import os
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from core.manifest import FrameProblem
    from core.session import Session


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("session", help="inspect and verify a capture session")
    actions = parser.add_subparsers(dest="session_command", metavar="ACTION", required=True)
    verify = actions.add_parser(
        "verify", help="re-hash every frame; non-zero exit if any is missing or corrupt"
    )
    verify.add_argument("session", type=Path)
    verify.set_defaults(func=handle_verify)
    info = actions.add_parser("info", help="views, illuminations, frames, devices, calibration")
    info.add_argument("session", type=Path)
    info.set_defaults(func=handle_info)


def handle_verify(args: argparse.Namespace) -> int:
    from core.manifest import verify_frames
    from core.manifest_check import session_problems
    from core.session import Session
    from rig.console import console as plain_console

    session = Session.open(args.session, bound_views=False)
    console = plain_console(soft_wrap=True)
    problems = verify_frames(session.root, session.frames)
    problems += companion_problems(session)
    counts = Counter(r.frame for r in session.frames)
    shared = session_problems(session.root, session.frames)
    duplicates = [text for kind, text in shared if kind == "duplicate"]
    for problem in problems:
        console.print(
            f"{problem.problem:<14} frame {problem.record.frame} (view "
            f"{problem.record.view}, {problem.record.illumination}): "
            f"{problem.record.path}",
            highlight=False,
        )
    for text in duplicates:
        console.print(f"duplicate      {text}", highlight=False)
    planned = session.info.plan.frames
    missing_planned = (planned - len(counts)) if planned is not None else 0
    strays = stray_files(session)
    for line in strays:
        console.print(line, highlight=False)
    ok = not problems and not duplicates and not strays
    summary = (
        f"{len(session.frames)} frames checked, {len(problems)} missing or corrupt, "
        f"{len(duplicates)} duplicated, {len(strays)} orphaned, quarantined or off-plan"
    )
    if missing_planned > 0:
        summary += (
            f"; {missing_planned} planned frames not captured yet "
            f"(`rig capture --resume {session.root}`)"
        )
    console.print(("ok: " if ok else "problems: ") + summary,
                  style="green" if ok else "bold red")
    return 0 if ok else 1


def stray_files(session: Session) -> list[str]:
    """Files no manifest line owns (orphans, unfinished downloads), quarantined files, and
    lines naming a view beyond the plan: each makes the session not verified."""
    from core.manifest import record_paths
    from rig.capture.frames import INCOMING
    from rig.capture.resume import QUARANTINE_DIR, REASONS_FILE

    owned = {p for r in session.frames for p in record_paths(r)}
    lines = []
    raw = session.raw_dir
    for folder in (raw, raw / INCOMING):
        if folder.is_dir():
            lines += [
                f"orphan         {f.relative_to(session.root).as_posix()} (no manifest line; "
                f"`rig capture --resume {session.root}` re-adopts or quarantines it)"
                for f in sorted(folder.iterdir())
                if f.is_file() and f.relative_to(session.root).as_posix() not in owned
            ]
    quarantine = session.root / QUARANTINE_DIR
    if quarantine.is_dir():
        lines += [
            f"quarantined    {QUARANTINE_DIR}/{f.name} (see {QUARANTINE_DIR}/{REASONS_FILE})"
            for f in sorted(quarantine.iterdir())
            if f.is_file() and f.name != REASONS_FILE and not f.name.startswith("manifest-")
        ]
    views = session.info.plan.views
    if views is not None:
        lines += [
            f"off-plan       frame {r.frame}: view {r.view} (the plan has {views} views)"
            for r in session.frames
            if r.view >= views
        ]
    return lines


def companion_problems(session: Session) -> list[FrameProblem]:
    """Files delivered with a frame (e.g. a JPEG beside the RAW) are checked like the frame."""
    from core.files import sha256_file
    from core.manifest import FrameProblem
    from core.manifest_check import leads_out

    problems = []
    for record in session.frames:
        for other in record.extra.get("other_files", []):
            file = session.root / other["path"]
            if os.path.lexists(file) and leads_out(session.root, file):
                problems.append(FrameProblem(record, f"link out {other['path']}"))
            elif not file.is_file():
                problems.append(FrameProblem(record, f"missing {other['path']}"))
            elif sha256_file(file) != other["sha256"]:
                problems.append(FrameProblem(record, f"hash mismatch {other['path']}"))
    return problems


def handle_info(args: argparse.Namespace) -> int:
    from core.session import Session
    from rig.console import console as plain_console

    session = Session.open(args.session)
    console = plain_console(soft_wrap=True)
    for line in summarise(session):
        console.print(line, highlight=False)
    return 0


def summarise(session: Session) -> list[str]:
    """Human-readable summary lines of a session."""
    from core.manifest import record_paths

    info = session.info
    plan = info.plan
    frames = session.frames
    by_label = Counter(f.illumination for f in frames)
    size = sum(
        (session.root / p).stat().st_size
        for f in frames
        for p in record_paths(f)
        if (session.root / p).is_file()
    )
    rows: list[tuple[str, str]] = [
        ("session", str(session.root)),
        ("profile", f"{info.profile_name or '?'} ({info.profile_source or '?'})"),
        ("created", info.created or "?"),
        ("views", f"{len(session.views())} of {_or_unknown(plan.views)} planned"),
        ("illuminations", ", ".join(f"{k} ×{v}" for k, v in sorted(by_label.items())) or "-"),
        ("frames", f"{len(frames)} of {_or_unknown(plan.frames)} planned, {size / 1e6:.1f} MB"),
        ("duration", _duration(frames)),
    ]
    runs = info.runs
    if runs:
        rows.append(("runs", f"{len(runs)}: " + ", ".join(str(r.get("status")) for r in runs)))
    for kind, desc in info.devices.items():
        desc = dict(desc)
        driver = desc.pop("driver", "?")
        details = ", ".join(f"{k}={v}" for k, v in desc.items() if not isinstance(v, (dict, list)))
        rows.append((kind, f"{driver}: {details}"))
    cal = info.calibration
    if cal.snapshot:
        lights = ", ".join(f"{k}->{v}" for k, v in cal.lights.items())
        rows.append(
            (
                "calibration",
                f"{cal.store} (snapshot in {cal.snapshot}/): camera {cal.camera}; "
                f"lights {lights}",
            )
        )
    else:
        rows.append(("calibration", "none recorded"))
    flat = cal.flat_field
    rows.append(
        (
            "flat field",
            "none (frames not corrected for lens fall-off)"
            if flat is None
            else f"{flat.entry} v{flat.version} ({flat.method or 'unknown method'})",
        )
    )
    for check in info.exposure_checks.values():
        if isinstance(check, dict) and check.get("suggestion"):
            rows.append(("exposure", check["suggestion"]))
    if info.notes:
        rows.append(("notes", info.notes))
    if info.ground_truth:
        rows.append(("ground truth", f"{info.ground_truth}/ (simulated rig)"))
    return [f"{label:<14}{value}" for label, value in rows]


def _or_unknown(count: int | None) -> str:
    return "?" if count is None else str(count)


def _duration(frames: list[Any]) -> str:
    stamps = []
    for frame in frames:
        try:
            stamps.append(dt.datetime.fromisoformat(frame.timestamp))
        except (TypeError, ValueError):
            continue
    if len(stamps) < 2:
        return "-"
    seconds = (max(stamps) - min(stamps)).total_seconds()
    return f"{seconds / 60:.1f} min ({seconds:.0f} s from first to last frame)"
