"""The run loop: interpret a plan's messages against the devices, record every frame, stop
cleanly on Ctrl-C, leave a resumable session on any failure."""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text

from core import interrupts
from core.errors import RigError
from core.manifest import FrameRecord
from core.session import RAW_DIR
from core.text import printable
from drivers.protocols import LightSource
from rig.capture.board_check import look_for_board
from rig.capture.coverage import coverage_hint
from rig.capture.devices import Ask, RigDevices, device_errors
from rig.capture.frames import INCOMING, ExposureCheck, RawData, check_exposure, store_frame
from rig.plans import (
    FrameSpec,
    MoveProjector,
    MoveTo,
    Msg,
    SetLight,
    ShowPattern,
    Trigger,
    capture_plan,
    pattern_image,
)
from rig.profile import Profile

BOARD_MIN_CORNERS = 6  # fewer and the view gets no board pose
BOARD_MIN_CONTRAST = 0.2  # paper - ink, fraction of 8-bit full scale
CAPTURE_ATTEMPTS = 3


class CaptureStopped(RigError):
    """The person stopped the capture (Ctrl-C or 'q'); the session is resumable."""


@dataclass
class RunState:
    """What the loop has done in this run; the session records it."""

    done: set[int]
    total: int
    captured: int = 0
    exposure_checks: dict[str, dict[str, Any]] = field(default_factory=dict)
    views_done: list[int] = field(default_factory=list)
    board_checks: dict[int, dict[str, Any]] = field(default_factory=dict)


class StopRequest:
    """First Ctrl-C (or SIGTERM): finish the frame in flight, then stop. Second Ctrl-C: stop
    now, the frame in flight is discarded (its files are orphans, removed on resume)."""

    def __init__(self, console: Console) -> None:
        self.requested = False
        self._console = console

    def __call__(self, signum: int, frame: Any) -> None:
        interrupts.note(signum)  # the command then exits 128 + signum
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        self._console.print(
            "stopping after the frame in flight (Ctrl-C again to discard it and stop now)",
            style="yellow",
        )

    @contextmanager
    def installed(self) -> Iterator[None]:
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        previous = {s: signal.signal(s, self) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)


def view_directions(devices: RigDevices, profile: Profile) -> list[tuple[float, float]]:
    """(azimuth, elevation) per view: where a self-positioning rig goes, else the profile's
    planned rings."""
    n = profile.plan.views
    positioner = devices.positioner
    if positioner is not None:
        directions = positioner.view_directions()
        if len(directions) >= n:
            return directions[:n]
    return [profile.plan.trajectory.view_direction(v, n) for v in range(n)]


def view_of(view: int, n_views: int) -> str:
    """A view as every message names it: its number from 0 (as in the manifest, file names and
    `rig relight --view`), with how far along the plan it is."""
    return f"view {view} ({view + 1}/{n_views})"


def _lit(levels: Mapping[str, float]) -> dict[str, float]:
    return {k: float(v) for k, v in levels.items() if v > 0}


class RunEngine:
    """Interprets plan messages (Bluesky's RunEngine, reduced to what a capture needs)."""

    def __init__(
        self,
        session_dir: Path,
        profile: Profile,
        devices: RigDevices,
        frames: list[FrameSpec],
        state: RunState,
        *,
        ask: Ask | None,
        console: Console,
        on_frame: Callable[[FrameRecord], None] | None = None,
    ) -> None:
        self.session_dir = session_dir
        self.profile = profile
        self.devices = devices
        self.frames = frames
        self.state = state
        self.ask = ask
        self.console = console
        self.on_frame = on_frame
        self.stop = StopRequest(console)
        self.directions = view_directions(devices, profile)
        self.progress: Progress | None = None

    def run(self) -> RunState:
        progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=self.console,
            transient=False,
        )
        self.progress = progress
        task = progress.add_task("capture", total=self.state.total, completed=len(self.state.done))
        placements = self.profile.plan.projector
        messages = capture_plan(
            self.frames,
            self.state.done,
            self.profile.plan.views,
            placements.count if placements else 0,
        )
        with self.stop.installed(), progress:
            try:
                self._interpret(messages, progress, task)
            except KeyboardInterrupt:  # second Ctrl-C: the frame in flight is discarded
                raise self._stopped("the frame in flight was discarded") from None
        self._switch_off()
        return self.state

    def _interpret(self, messages: Iterator[Msg], progress: Progress, task: TaskID) -> None:
        for msg in messages:
            if self.stop.requested:
                raise self._stopped()
            if isinstance(msg, MoveProjector):
                self._move_projector(msg)
            elif isinstance(msg, MoveTo):
                self._move_to(msg)
            elif isinstance(msg, SetLight):
                self._set_light(msg.illumination)
            elif isinstance(msg, ShowPattern):
                self._show_pattern(msg.pattern)
            elif isinstance(msg, Trigger):
                self._trigger(msg.spec)
                progress.update(
                    task,
                    advance=1,
                    description=f"{view_of(msg.spec.view, self.profile.plan.views)} "
                    f"{msg.spec.label}",
                )

    def _stopped(self, note: str = "") -> CaptureStopped:
        self._switch_off()
        done = len(self.state.done)
        return CaptureStopped(
            f"capture stopped after {done} of {self.state.total} frames "
            f"({self.state.captured} in this run); every completed frame is saved"
            + (f", {note}" if note else ""),
            f"resume with `rig capture --resume {self.session_dir}`",
        )

    def _prompt(self, text: str) -> str:
        assert self.ask is not None
        if self.progress is not None:
            self.progress.stop()
        default = signal.getsignal(signal.SIGINT)
        in_main = threading.current_thread() is threading.main_thread()
        if in_main:  # Ctrl-C at a prompt stops at once: nothing is in flight
            signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            return self.ask(text)
        except (KeyboardInterrupt, EOFError):
            raise self._stopped() from None
        finally:
            if in_main:
                signal.signal(signal.SIGINT, default)
            if self.progress is not None:
                self.progress.start()

    def _move_projector(self, msg: MoveProjector) -> None:
        """Camera and projector are moved alternately: now the projector, the camera stays."""
        text = (
            f"move the projector to placement {msg.placement + 1}/{msg.n_placements} "
            "(leave the camera where it is; aim the projector at the object from a new side)"
        )
        if self.ask is not None and self.devices.positioner is None:
            answer = self._prompt(text[0].upper() + text[1:] + ", then press Enter (q to stop) ")
            if answer.strip().lower() in ("q", "quit", "stop"):
                raise self._stopped()
        else:
            self.console.print(f"projector: {text}", highlight=False)

    def _move_to(self, msg: MoveTo) -> None:
        hint = coverage_hint(
            self.directions,
            self.state.views_done,
            msg.view,
            self.profile.plan.trajectory.distance_factor(msg.view),
        )
        if self.ask is not None and self.devices.positioner is None:
            light = (
                ", hold the light at a new place on the camera's side"
                if self.profile.light_mount.type == "free"
                else ""
            )
            what = (
                "Move the camera (not the projector)"
                if self.profile.plan.projector is not None
                else "Move the plate"
            )
            answer = self._prompt(
                f"{what} to {view_of(msg.view, msg.n_views)}{light} "
                f"({hint}) and press Enter (q + Enter to stop) "
            )
            if answer.strip().lower() in ("q", "quit", "stop"):
                raise self._stopped()
        else:
            self.console.print(f"{view_of(msg.view, msg.n_views)}: {hint}", highlight=False)
        self.devices.goto_view(msg.view)
        if msg.view not in self.state.views_done:
            self.state.views_done.append(msg.view)

    def _set_light(self, illumination: str | None) -> None:
        light, projector = self.devices.light, self.devices.projector
        if light is not None:
            if projector is not None:
                with device_errors("projector", self.devices.names["projector"], "blank"):
                    projector.blank()
            with device_errors(
                "light", self.devices.names["light"], f"switch to {illumination or 'off'}"
            ):
                if illumination is None:
                    light.off()
                else:
                    self._switch_light(light, illumination)
        elif projector is not None:
            levels = self.profile.illuminations.get(illumination or "", {})
            rgb = np.array([levels.get(c, 0.0) for c in ("r", "g", "b")])
            image = np.broadcast_to(rgb, (projector.height, projector.width, 3)).copy()
            with device_errors(
                "projector", self.devices.names["projector"], f"show {illumination or 'black'}"
            ):
                projector.show(image) if illumination else projector.blank()
        if self.profile.plan.settle_s > 0:
            time.sleep(self.profile.plan.settle_s)

    def _switch_light(self, light: LightSource, name: str) -> None:
        """By name when the light knows this illumination with the profile's levels (named
        prompts, the driver's settle time), else by the profile's channel levels."""
        levels = self.profile.illuminations[name]
        known = dict(getattr(light, "illuminations", {}) or {}).get(name)
        if known is not None and _lit(known) == _lit(levels):
            light.set_illumination(name)
        else:
            light.set_levels(levels)

    def _show_pattern(self, pattern: str) -> None:
        projector = self.devices.projector
        assert projector is not None
        with device_errors("projector", self.devices.names["projector"], f"show {pattern}"):
            projector.show(pattern_image(pattern, projector.width, projector.height))
        if self.profile.plan.settle_s > 0:
            time.sleep(self.profile.plan.settle_s)

    def _trigger(self, spec: FrameSpec) -> None:
        """Capture and store one frame; a file that fails verification (a torn download) is
        discarded and the frame shot again, up to CAPTURE_ATTEMPTS times."""
        incoming = self.session_dir / RAW_DIR / INCOMING
        where = f"frame {spec.frame} (view {spec.view}, {spec.label})"
        for attempt in range(1, CAPTURE_ATTEMPTS + 1):
            stem = f"f{spec.frame:05d}" + (f"_{attempt}" if attempt > 1 else "")
            with device_errors("camera", self.devices.names["camera"], f"capture {where}"):
                captured = self.devices.camera.capture(incoming, stem)
            try:
                record, raw = store_frame(self.session_dir, spec, captured)
                break
            except RigError as exc:
                for path in captured.paths:
                    Path(path).unlink(missing_ok=True)
                if attempt == CAPTURE_ATTEMPTS:
                    raise RigError(f"{where}: {exc.problem}", exc.fix) from exc
                self.console.print(
                    Text(printable(f"{where}: {exc.problem} — capturing it again"), "yellow")
                )
        self.state.done.add(spec.frame)
        self.state.captured += 1
        board = None
        lit = spec.kind == "illumination" or spec.label == "white"  # not ambient or stripes
        if self.profile.board is not None and lit and spec.view not in self.state.board_checks:
            board = self._check_board(record, raw, spec)
        if spec.kind == "illumination" and spec.label not in self.state.exposure_checks:
            check = self._check_exposure(record, raw, spec)
            entry = check.as_dict()
            if self.profile.board is not None:
                if board is None or board["frame"] != spec.frame:
                    board = self._board_report(record, raw)
                entry["board_contrast"] = board["contrast"]
                self._warn_board_contrast(spec.label, check, board)
            self.state.exposure_checks[spec.label] = entry
        if self.on_frame is not None:
            self.on_frame(record)

    def _warn_board_contrast(
        self, label: str, check: ExposureCheck, board: Mapping[str, Any]
    ) -> None:
        """A board found but faint (dim, or paper and ink both clipped) gets an exposure hint."""
        if board["corners"] < BOARD_MIN_CORNERS or board["contrast"] >= BOARD_MIN_CONTRAST:
            return
        fix = (
            "shorten the exposure (the paper clips)"
            if check.saturated_fraction > 0.001
            else "lengthen the exposure or add light"
        )
        self.console.print(
            f"exposure: {label}: the board's paper/ink contrast is only "
            f"{board['contrast']:.2f} (want {BOARD_MIN_CONTRAST}) — {fix}",
            style="yellow",
        )

    def _board_report(self, record: FrameRecord, raw: RawData) -> dict[str, Any]:
        """Corners found and paper/ink contrast of the board in a frame (``binning``: of the
        look they were found in)."""
        assert self.profile.board is not None
        look = look_for_board(raw, self.profile.board, BOARD_MIN_CORNERS)
        return {
            "frame": record.frame,
            "corners": look.corners,
            "contrast": round(look.contrast, 4),
            "binning": look.binning,
        }

    def _check_board(self, record: FrameRecord, raw: RawData, spec: FrameSpec) -> dict[str, Any]:
        """On a view's first lit frame: warn when the board is not visible enough for a pose."""
        report = self._board_report(record, raw)
        self.state.board_checks[spec.view] = report
        if report["corners"] < BOARD_MIN_CORNERS:
            self.console.print(
                f"board: view {spec.view}: only {report['corners']} board corners "
                f"found (need {BOARD_MIN_CORNERS}) — keep more of the board in the frame, "
                "away from the object's shadow and glare",
                style="yellow",
            )
        return report

    def _check_exposure(self, record: FrameRecord, raw: RawData, spec: FrameSpec) -> ExposureCheck:
        check = check_exposure(raw, spec.label, record.exposure_s)
        if check.suggestion:
            self.console.print(f"exposure: {check.suggestion}", style="yellow")
        return check

    def _switch_off(self) -> None:
        try:
            if self.devices.light is not None:
                self.devices.light.off()
            if self.devices.projector is not None:
                self.devices.projector.blank()
        except Exception:  # switching off is a courtesy; the session is already safe
            return
