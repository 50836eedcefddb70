"""Guided capture sessions (``rig capture``) as a library call: :func:`run_capture`."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.text import Text

from core.errors import RigError
from core.lock import locked
from core.manifest import FrameRecord
from core.session import POSES_DIR, SESSION_FILE
from core.session_info import PlanInfo, SessionInfo
from core.text import printable
from rig.capture.devices import Ask, RigDevices, open_devices
from rig.capture.engine import CaptureStopped, RunEngine, RunState
from rig.capture.resume import prepare_resume
from rig.capture.session_dir import (
    FORMAT_VERSION,
    GROUND_TRUTH_DIR,
    check_new_session_dir,
    discard_unstarted_session,
    new_session_dir,
    now,
    read_info,
    snapshot_calibration,
    snapshot_profile,
    software_versions,
    write_info,
)
from rig.capture.trust import confirm_session_devices, stdin_is_tty
from rig.console import console as plain_console
from rig.plans import frame_list
from rig.profile import Profile, load_profile

__all__ = ["CaptureStopped", "DeviceFactory", "run_capture"]

DeviceFactory = Callable[[Profile, int, Ask | None], RigDevices]


def run_capture(
    profile: Profile | str | Path | None,
    out_dir: Path | str,
    *,
    yes: bool = False,
    resume: bool = False,
    seed: int | None = None,
    console: Console | None = None,
    ask: Ask | None = None,
    open_rig: DeviceFactory = open_devices,
    on_frame: Callable[[FrameRecord], None] | None = None,
    notes: str = "",
    trust_devices: bool = False,
) -> Path:
    """Capture (or with ``resume`` continue) a session into ``out_dir`` and return it.

    ``yes`` runs without prompts (sim, automation); ``ask`` replaces the console prompt;
    ``open_rig`` replaces device opening (tests, other front ends); ``notes`` go into
    session.yaml (object, operator, conditions); ``trust_devices`` lets a resume open
    devices whose snapshot runs a program without asking (rig.capture.trust). Raises
    :class:`CaptureStopped` when the person stops, RigError on any failure — in both cases
    every completed frame is on disk and ``resume=True`` continues where it stopped. The
    session folder is locked (core.lock) for the whole call: a second capture, a resume or a
    reconstruction of it meanwhile is refused."""
    out = Path(out_dir).expanduser().resolve()
    with locked(out, "rig capture --resume" if resume else "rig capture", create=True):
        return _capture(
            profile,
            out,
            yes=yes,
            resume=resume,
            seed=seed,
            console=console,
            ask=ask,
            open_rig=open_rig,
            on_frame=on_frame,
            notes=notes,
            trust_devices=trust_devices,
        )


def _capture(
    profile: Profile | str | Path | None,
    out: Path,
    *,
    yes: bool,
    resume: bool,
    seed: int | None,
    console: Console | None,
    ask: Ask | None,
    open_rig: DeviceFactory,
    on_frame: Callable[[FrameRecord], None] | None,
    notes: str,
    trust_devices: bool,
) -> Path:
    console = console or plain_console(stderr=True)
    interactive = ask is not None or stdin_is_tty()
    if not yes and ask is None:
        ask = console.input
    prompt = None if yes else ask
    if resume and (out / SESSION_FILE).is_file():
        info = read_info(out)
        if profile is not None and not isinstance(profile, Profile):
            console.print("resuming with the session's own profile snapshot", style="dim")
        profile = snapshot_profile(out)
        typed = SessionInfo.from_mapping(info, str(out / SESSION_FILE))
        recorded = typed.plan
        seed = (typed.seed or 0) if seed is None else seed
        confirm_session_devices(
            out, profile, trusted=trust_devices, ask=prompt, interactive=interactive
        )
        records = prepare_resume(
            out, frame_list(profile.plan, recorded.projector_size), _warner(console)
        )
    else:
        if profile is None:
            raise RigError(
                f"{out} has no session to resume" if resume else "no profile given",
                "give --profile to start a new session",
            )
        if resume:  # killed before session.yaml existed: nothing was captured, start afresh
            discard_unstarted_session(out)
        profile = profile if isinstance(profile, Profile) else load_profile(profile)
        seed = 0 if seed is None else seed
        check_new_session_dir(out)
        info = None
        recorded = None
        records = []
    devices = open_rig(profile, seed, prompt)
    try:
        size = (devices.projector.width, devices.projector.height) if devices.projector else None
        frames = frame_list(profile.plan, size)
        if info is None:
            info = _start_session(out, profile, devices, seed, len(frames), size)
            info["notes"] = notes
        elif recorded is not None:
            _check_same_plan(out, recorded, len(frames), size)
        state = RunState(
            done={r.frame for r in records},
            total=len(frames),
            exposure_checks=dict(info.get("exposure_checks") or {}),
            views_done=sorted({r.view for r in records}),
            board_checks={int(k): v for k, v in (info.get("board_checks") or {}).items()},
        )
        run: dict[str, Any] = {
            "started": now(),
            "ended": None,
            "status": "running",
            "devices": devices.describe(),
        }
        info.setdefault("runs", []).append(run)
        try:
            write_info(out, info)
        except BaseException:
            if not (out / SESSION_FILE).exists():  # a new session (a full disk): leave none
                discard_unstarted_session(out)
            raise
        engine = RunEngine(
            out, profile, devices, frames, state, ask=prompt, console=console, on_frame=on_frame
        )
        try:
            engine.run()
            run["status"] = "complete"
        except CaptureStopped:
            run["status"] = "stopped"
            raise
        except BaseException as exc:
            run["status"] = f"failed: {exc}"
            if isinstance(exc, RigError):
                raise RigError(
                    exc.problem,
                    f"{exc.fix + '; ' if exc.fix else ''}every completed "
                    f"frame is saved — fix it and run `rig capture --resume {out}`",
                ) from exc
            raise
        finally:
            run["ended"] = now()
            run["frames"] = state.captured
            info["exposure_checks"] = state.exposure_checks
            if state.board_checks:
                info["board_checks"] = state.board_checks
            info["frames_done"] = len(state.done)
            write_info(out, info)
    finally:
        devices.close()
    console.print(Text.assemble(("capture complete:", "green"),
                                f" {len(state.done)} frames in {printable(out)}"))
    return out


def _warner(console: Console) -> Callable[[str], None]:
    return lambda text: console.print(Text.assemble(("resume:", "yellow"), " ", printable(text)))


def _start_session(
    out: Path,
    profile: Profile,
    devices: RigDevices,
    seed: int,
    n_frames: int,
    projector_size: tuple[int, int] | None,
) -> dict[str, Any]:
    """Create the session directory; if setting it up fails (a missing calibration entry...),
    empty it again so the same --out can be used once the problem is fixed (the lock removes
    a folder it made)."""
    new_session_dir(out)
    try:
        return _new_info(out, profile, devices, seed, n_frames, projector_size)
    except BaseException:
        discard_unstarted_session(out)
        raise


def _check_same_plan(
    out: Path, plan: PlanInfo, n_frames: int, projector_size: tuple[int, int] | None
) -> None:
    """Frame numbers are only the resume point if the plan expands the same way."""
    recorded = plan.projector_size
    if plan.frames != n_frames or (recorded and recorded != projector_size):
        raise RigError(
            f"{out}: the rig now plans {n_frames} frames (projector {projector_size}), the "
            f"session was started with {plan.frames} (projector {recorded})",
            "resume with the same projector resolution, or start a new session",
        )


def _new_info(
    out: Path,
    profile: Profile,
    devices: RigDevices,
    seed: int,
    n_frames: int,
    projector_size: tuple[int, int] | None,
) -> dict[str, Any]:
    """session.yaml for a new session; also the calibration snapshot and sim ground truth."""
    calibration = snapshot_calibration(profile.calibration, out, profile.source)
    plan = profile.plan
    info: dict[str, Any] = {
        "format": FORMAT_VERSION,
        "created": now(),
        "profile_name": profile.name,
        "profile_source": profile.source,
        "profile": dict(profile.data),
        "seed": seed,
        "plan": {
            "views": plan.views,
            "illuminations": list(plan.illuminations),
            "ambient": plan.ambient,
            "structured_light": bool(plan.structured_light),
            "frames": n_frames,
            "projector_size": list(projector_size) if projector_size else None,
            "projector_placements": None
            if plan.projector is None
            else {
                "placements": plan.projector.count,
                "views_per_placement": plan.projector.views_per_placement,
            },
        },
        "light_mount": {
            "type": profile.light_mount.type,
            "offset_m": list(profile.light_mount.offset_m)
            if profile.light_mount.offset_m
            else None,
            "diameter_m": profile.light_mount.diameter_m,
        },
        # reconstruct.poses.sfm reads the camera-centre distances as this list (metric scale)
        "known_distances": [pair.as_dict() for pair in profile.camera_pairs],
        "known_lengths": dict(profile.known_distances),
        "calibration": calibration,
        "software": software_versions(),
        "devices": devices.describe(),
        "notes": "",
    }
    if profile.board is not None:  # the poses stage reads the board from here
        info["board"] = profile.board.to_dict()
    truth = devices.ground_truth
    if truth is not None:
        truth.write_ground_truth(out / GROUND_TRUTH_DIR)
        info["ground_truth"] = GROUND_TRUTH_DIR
        if profile.poses == "known":
            _write_known_poses(out)
            info["poses"] = POSES_DIR
    return info


def _write_known_poses(out: Path) -> None:
    """SESSION/poses/: the true poses (COLMAP text, images named as the decode stage
    names views)."""
    shutil.copytree(out / GROUND_TRUTH_DIR / POSES_DIR, out / POSES_DIR)
