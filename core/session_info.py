"""``session.yaml`` as typed, frozen values: :class:`SessionInfo`.

The file is a public format (written by ``rig capture`` and by other tools) and is read here
only; a writer that round-trips it (``rig capture --resume``) keeps its own mapping. Keys
that only some sessions have are optional. The camera intrinsics, the board and the known
camera distances may also sit in the ``profile`` snapshot; the top level wins. A value of
the wrong type is one :class:`RigError` naming the file and the key.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from core.errors import RigError

FIX = "fix that key in session.yaml (or restore the file from a backup)"


def _show(value: Any) -> str:
    shown = repr(value)
    return shown if len(shown) <= 60 else shown[:57] + "..."


class _Reader:
    """Typed reads of one session.yaml mapping; errors name ``where`` and the key."""

    def __init__(self, data: Mapping[str, Any], where: str) -> None:
        self.data = data
        self.where = where

    def bad(self, key: str, value: Any, want: str) -> RigError:
        return RigError(f"{self.where}: `{key}` is {_show(value)}, expected {want}", FIX)

    def get(self, key: str) -> Any:
        """The value at a dotted ``key`` (None where any part is missing)."""
        node: Any = self.data
        for part in key.split("."):
            node = node.get(part) if isinstance(node, Mapping) else None
        return node

    def mapping(self, key: str) -> Mapping[str, Any]:
        value = self.get(key)
        if value is None:
            return {}
        if not isinstance(value, Mapping):
            raise self.bad(key, value, "a mapping")
        return value

    def text(self, key: str) -> str | None:
        value = self.get(key)
        return None if value is None else str(value)

    def whole(self, key: str, positive: bool = False) -> int | None:
        value = self.get(key)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int) or (positive and value <= 0):
            raise self.bad(key, value, "a whole number > 0" if positive else "a whole number")
        return value

    def numbers(self, key: str, value: Any, count: int | None = None) -> tuple[float, ...]:
        ok = isinstance(value, (list, tuple)) and (count is None or len(value) == count)
        if ok:
            ok = all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value
            )
        if not ok:
            raise self.bad(key, value, f"a list of {count or 'some'} numbers")
        return tuple(float(v) for v in value)

    def size(self, key: str) -> tuple[int, int] | None:
        value = self.get(key)
        if value is None:
            return None
        width, height = self.numbers(key, value, 2)
        if width <= 0 or height <= 0 or width != int(width) or height != int(height):
            raise self.bad(key, value, "[width, height] in pixels")
        return int(width), int(height)

    def in_profile(self, key: str) -> tuple[str, Any]:
        """``key`` at the top level, else in the profile snapshot: (where it was, value)."""
        value = self.get(key)
        if value is not None:
            return key, value
        return f"profile.{key}", self.get(f"profile.{key}")


@dataclass(frozen=True)
class PlanInfo:
    """``plan``: what the capture set out to take (None where the session does not say)."""

    views: int | None = None
    illuminations: tuple[str, ...] | None = None  # the lit frames; ambient/patterns are not
    frames: int | None = None
    projector_size: tuple[int, int] | None = None  # (width, height)
    projector_placements: Mapping[str, Any] | None = None  # {placements, views_per_placement}


@dataclass(frozen=True)
class FlatFieldChoice:
    """``calibration.flat_field``: the snapshot's flat-field entry and version, and how it
    was made (``method``: white card, lensfun)."""

    entry: str
    version: int
    method: str = ""


@dataclass(frozen=True)
class CalibrationInfo:
    """``calibration``: the store entries the session's snapshot in ``calibration/`` holds."""

    snapshot: str | None = None
    store: str | None = None
    camera: str | None = None
    lights: Mapping[str, str] = field(default_factory=dict)  # illumination -> store entry
    flat_field: FlatFieldChoice | None = None  # the lens fall-off correction decode applies


@dataclass(frozen=True)
class CameraIntrinsics:
    """``intrinsics`` (or ``camera.intrinsics``): a COLMAP camera model and its parameters."""

    model: str
    width: int
    height: int
    params: tuple[float, ...]


@dataclass(frozen=True)
class KnownDistance:
    """One ``known_distances`` entry: the measured distance between two camera centres."""

    views: tuple[int, int]
    metres: float


@dataclass(frozen=True)
class SessionInfo:
    """The typed content of ``session.yaml``."""

    plan: PlanInfo = field(default_factory=PlanInfo)
    calibration: CalibrationInfo = field(default_factory=CalibrationInfo)
    intrinsics: CameraIntrinsics | None = None
    known_distances: tuple[KnownDistance, ...] = ()
    known_lengths: Mapping[str, float] = field(default_factory=dict)
    board: Mapping[str, Any] | None = None  # parsed by reconstruct.poses.board.BoardSpec
    light_offset_m: tuple[float, ...] | None = None  # light_mount.offset_m
    light_diameter_m: float = 0.0  # light_mount.diameter_m (0: a point light)
    devices: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    poses: str | None = None  # folder of known poses (COLMAP text), relative to the session
    ground_truth: str | None = None  # sim sessions: folder of the true scene
    profile_name: str | None = None
    profile_source: str | None = None
    created: str | None = None
    seed: int | None = None
    notes: str = ""
    runs: tuple[Mapping[str, Any], ...] = ()
    exposure_checks: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    board_checks: Mapping[int, Mapping[str, Any]] = field(default_factory=dict)  # by view
    software: Mapping[str, str] = field(default_factory=dict)

    @property
    def projector_size(self) -> tuple[int, int] | None:
        """The plan's projector size, else the projector device's recorded resolution."""
        if self.plan.projector_size is not None:
            return self.plan.projector_size
        res = (self.devices.get("projector") or {}).get("resolution")
        return (int(res[0]), int(res[1])) if res else None

    @classmethod
    def from_mapping(cls, data: Any, where: str = "session.yaml") -> SessionInfo:
        if data is None:
            data = {}
        if not isinstance(data, Mapping):
            raise RigError(f"{where} is not a mapping ({type(data).__name__})", FIX)
        read = _Reader(data, where)
        devices = read.mapping("devices")
        for kind, desc in devices.items():
            if not isinstance(desc, Mapping):
                raise read.bad(f"devices.{kind}", desc, "a mapping")
        runs = read.get("runs") or []
        if not isinstance(runs, list) or not all(isinstance(r, Mapping) for r in runs):
            raise read.bad("runs", runs, "a list of mappings")
        board_key, board = read.in_profile("board")
        if board is not None and not isinstance(board, Mapping):
            raise read.bad(board_key, board, "a mapping (the board: snippet of `rig board`)")
        offset = read.get("light_mount.offset_m")
        diameter = read.get("light_mount.diameter_m")
        return cls(
            plan=_plan(read),
            calibration=_calibration(read),
            intrinsics=_intrinsics(read),
            known_distances=_known_distances(read),
            known_lengths={str(k): v for k, v in read.mapping("known_lengths").items()},
            board=board,
            light_offset_m=None if offset is None else read.numbers(
                "light_mount.offset_m", offset, 3
            ),
            light_diameter_m=0.0 if diameter is None else _diameter(read, diameter),
            devices=devices,
            poses=read.text("poses"),
            ground_truth=read.text("ground_truth"),
            profile_name=read.text("profile_name"),
            profile_source=read.text("profile_source"),
            created=read.text("created"),
            seed=read.whole("seed"),
            notes=read.text("notes") or "",
            runs=tuple(runs),
            exposure_checks=read.mapping("exposure_checks"),
            board_checks=_board_checks(read),
            software=read.mapping("software"),
        )


def _diameter(read: _Reader, value: Any) -> float:
    (diameter,) = read.numbers("light_mount.diameter_m", [value], 1)
    if diameter < 0:
        raise read.bad("light_mount.diameter_m", value, "a diameter in metres, 0 or more")
    return diameter


def _plan(read: _Reader) -> PlanInfo:
    read.mapping("plan")
    lit = read.get("plan.illuminations")
    if lit is not None and not (isinstance(lit, list) and all(isinstance(n, str) for n in lit)):
        raise read.bad("plan.illuminations", lit, "a list of illumination names")
    return PlanInfo(
        views=read.whole("plan.views", positive=True),
        illuminations=None if lit is None else tuple(lit),
        frames=read.whole("plan.frames"),
        projector_size=read.size("plan.projector_size"),
        projector_placements=read.mapping("plan.projector_placements") or None,
    )


def _board_checks(read: _Reader) -> dict[int, Mapping[str, Any]]:
    checks = read.mapping("board_checks")
    out: dict[int, Mapping[str, Any]] = {}
    for view, check in checks.items():
        if isinstance(view, bool) or not isinstance(view, int) or not isinstance(check, Mapping):
            raise read.bad(f"board_checks.{view}", check, "a view number -> {corners, ...}")
        out[view] = check
    return out


def _calibration(read: _Reader) -> CalibrationInfo:
    read.mapping("calibration")
    lights = read.mapping("calibration.lights")
    return CalibrationInfo(
        snapshot=read.text("calibration.snapshot"),
        store=read.text("calibration.store"),
        camera=read.text("calibration.camera"),
        lights={str(k): str(v) for k, v in lights.items()},
        flat_field=_flat_field(read),
    )


def _flat_field(read: _Reader) -> FlatFieldChoice | None:
    flat = read.get("calibration.flat_field")
    if flat is None:
        return None
    want = "{entry: NAME, version: N, method: ...}"
    if not isinstance(flat, Mapping) or "entry" not in flat:
        raise read.bad("calibration.flat_field", flat, want)
    version = read.whole("calibration.flat_field.version", positive=True)
    if version is None:
        raise read.bad("calibration.flat_field", flat, want)
    return FlatFieldChoice(str(flat["entry"]), version, str(flat.get("method") or ""))


def _intrinsics(read: _Reader) -> CameraIntrinsics | None:
    key, spec = read.in_profile("intrinsics")
    if spec is None:
        key, spec = read.in_profile("camera.intrinsics")
    if spec is None:
        return None
    want = "{model: PINHOLE, width: W, height: H, params: [fx, fy, cx, cy]}"
    if not isinstance(spec, Mapping) or not {"model", "width", "height", "params"} <= set(spec):
        raise read.bad(key, spec, want)
    try:
        width, height = int(spec["width"]), int(spec["height"])
        params = tuple(float(p) for p in spec["params"])
    except (TypeError, ValueError) as exc:
        raise read.bad(key, spec, want) from exc
    return CameraIntrinsics(str(spec["model"]), width, height, params)


def _known_distances(read: _Reader) -> tuple[KnownDistance, ...]:
    key, entries = read.in_profile("known_distances")
    if isinstance(entries, Mapping):  # a profile's own section: the pairs are camera_pairs
        key, entries = f"{key}.camera_pairs", entries.get("camera_pairs")
    if not entries:
        return ()
    if not isinstance(entries, list):
        raise read.bad(key, entries, "a list of {views: [a, b], metres: d}")
    out = []
    for i, entry in enumerate(entries):
        try:
            a, b = (int(v) for v in entry["views"])
            out.append(KnownDistance((a, b), float(entry["metres"])))
        except (KeyError, TypeError, ValueError) as exc:
            raise read.bad(f"{key}[{i}]", entry, "{views: [a, b], metres: d}") from exc
    return tuple(out)
