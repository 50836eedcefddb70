"""Make a session safe to append to without ever deleting a frame.

A kill can leave frame files that no manifest line owns (the manifest line was never
written, was torn, or the manifest was removed), and a disk or a person can change a frame
after its line was written. On resume every recorded frame is re-hashed; a file that no
longer matches its line is moved to ``quarantine/`` and its frame captured again. A file
that no line owns is re-adopted when it is the planned frame it is named after and decodes
(LibRaw/tifffile/NumPy), else it is moved to ``quarantine/`` too. Every move is logged in
``quarantine/reasons.jsonl`` with the reason; nothing is unlinked."""

from __future__ import annotations

import datetime as dt
import json
import os
import shutil
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from core.errors import RigError
from core.files import fsync_dir, sha256_file, write_bytes_atomically
from core.manifest import (
    MANIFEST_FILE,
    FrameRecord,
    append_manifest,
    read_manifest,
    record_paths,
)
from core.manifest_check import check_session
from core.session import RAW_DIR
from rig.capture.frames import INCOMING, frame_name, verify_file
from rig.plans import FrameSpec

QUARANTINE_DIR = "quarantine"
REASONS_FILE = "reasons.jsonl"

Warn = Callable[[str], None]


@dataclass(frozen=True)
class Orphan:
    """A file in raw/ that no manifest line owns, and the planned frame its name claims."""

    path: Path
    spec: FrameSpec | None
    index: int  # 0: the frame's main file; n: its n-th companion (e.g. the JPEG)


def _free_name(path: Path) -> Path:
    """``path``, or ``stem.N.suffix`` beside it for the first N not taken: nothing there is
    ever overwritten."""
    target, n = path, 1
    while target.exists():
        target = path.with_name(f"{path.stem}.{n}{path.suffix}")
        n += 1
    return target


def quarantine(session_dir: Path, file: Path, reason: str, warn: Warn) -> Path:
    """Move ``file`` into SESSION/quarantine/ (a free name), log why, and warn."""
    folder = session_dir / QUARANTINE_DIR
    folder.mkdir(exist_ok=True)
    target = _free_name(folder / file.name)
    os.replace(file, target)
    fsync_dir(folder)
    fsync_dir(file.parent)
    line = {
        "file": target.name,
        "was": file.relative_to(session_dir).as_posix(),
        "reason": reason,
        "time": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
    }
    with open(folder / REASONS_FILE, "a", encoding="utf-8") as handle:
        handle.write(json.dumps(line) + "\n")
        handle.flush()
        os.fsync(handle.fileno())
    warn(
        f"{line['was']}: {reason} — moved to {QUARANTINE_DIR}/{target.name} "
        "(kept; the frame is captured again)"
    )
    return target


def prepare_resume(session_dir: Path, frames: list[FrameSpec], warn: Warn) -> list[FrameRecord]:
    """Cut a torn last manifest line, check every line against the plan, re-hash recorded
    frames (quarantining mismatches), re-adopt or quarantine orphans; return the complete
    frames. Raises RigError when a recorded frame's file is missing (it is not captured
    again silently: the person may still have it)."""
    _check_folders(session_dir)
    _truncate_torn_line(session_dir / MANIFEST_FILE)
    n_views = 1 + max((s.view for s in frames), default=-1)
    records = _drop_quarantined(session_dir, read_manifest(session_dir, n_views))
    _check_against_plan(session_dir, records, frames)
    check_session(session_dir, records, session_dir / MANIFEST_FILE)
    missing = [r for r in records if not all((session_dir / p).is_file() for p in record_paths(r))]
    if missing:
        raise RigError(
            f"{len(missing)} frame(s) in the manifest are missing from raw/ "
            f"(first: frame {missing[0].frame}, {missing[0].path})",
            f"restore them, or run `rig session verify {session_dir}` for the list",
        )
    records = _rehash(session_dir, records, warn)
    owned = {p for r in records for p in record_paths(r)}
    raw = session_dir / RAW_DIR
    incoming = raw / INCOMING
    incoming.mkdir(parents=True, exist_ok=True)
    for file in sorted(incoming.iterdir()):  # a download cut by the kill, never verified
        if file.is_file():
            quarantine(session_dir, file, "an unfinished download", warn)
    done = {r.frame for r in records}
    orphans = [
        _classify(f, frames)
        for f in sorted(raw.iterdir())
        if f.is_file() and f"{RAW_DIR}/{f.name}" not in owned
    ]
    return records + _adopt(session_dir, orphans, done, records, warn)


def _check_folders(session_dir: Path) -> None:
    """Resume lists and moves files in these folders: a link out of the session (a foreign
    session's ``raw -> ~/Documents``) would have it move the person's own files."""
    root = session_dir.resolve()
    for name in (RAW_DIR, f"{RAW_DIR}/{INCOMING}", QUARANTINE_DIR, MANIFEST_FILE):
        path = session_dir / name
        if path.is_symlink() or (path.exists() and not path.resolve().is_relative_to(root)):
            raise RigError(
                f"{path} is a link{' out of the session' if path.exists() else ''}: resume "
                "moves files there and will not follow it",
                f"replace it with a real {'file' if name == MANIFEST_FILE else 'folder'} "
                "inside the session",
            )


def _drop_quarantined(session_dir: Path, records: list[FrameRecord]) -> list[FrameRecord]:
    """Drop the lines of frames whose files a re-hash already moved to quarantine/ when a kill
    stopped it before it rewrote the manifest (they are captured again, not reported missing)."""
    reasons = session_dir / QUARANTINE_DIR / REASONS_FILE
    if not reasons.is_file():
        return records
    moved = set()
    for line in reasons.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            entry = json.loads(line)
        except ValueError:
            continue  # a line torn by a kill
        if isinstance(entry, dict) and "sha256" in str(entry.get("reason")):
            moved.add(str(entry.get("was")))
    keep = [
        r for r in records
        if not any(p in moved and not (session_dir / p).is_file() for p in record_paths(r))
    ]
    if len(keep) < len(records):
        _rewrite_manifest(session_dir, keep)
    return keep


def _rewrite_manifest(session_dir: Path, records: list[FrameRecord]) -> None:
    """Replace the manifest with ``records``' lines, atomically."""
    lines = "".join(r.to_json() + "\n" for r in records)
    write_bytes_atomically(session_dir / MANIFEST_FILE, lines.encode())


def _check_against_plan(
    session_dir: Path, records: list[FrameRecord], frames: list[FrameSpec]
) -> None:
    """Each line names a planned frame once, with that frame's view and illumination."""
    where = session_dir / MANIFEST_FILE
    seen: set[int] = set()
    for record in records:
        if record.frame in seen:
            raise RigError(
                f"{where} lists frame {record.frame} twice",
                "the manifest was edited by hand; restore it from a backup",
            )
        seen.add(record.frame)
        spec = frames[record.frame] if record.frame < len(frames) else None
        if spec is None or (spec.view, spec.label) != (record.view, record.illumination):
            planned = "no such frame" if spec is None else f"view {spec.view}, {spec.label}"
            raise RigError(
                f"{where}: frame {record.frame} is recorded as view {record.view}, "
                f"{record.illumination!r} but the plan has {planned}",
                "the manifest belongs to another plan or was edited; restore it from a backup",
            )


def _rehash(session_dir: Path, records: list[FrameRecord], warn: Warn) -> list[FrameRecord]:
    """Quarantine the files of every frame whose hash no longer matches its manifest line and
    drop those lines (the old manifest is kept beside the quarantined files)."""
    bad: list[FrameRecord] = []
    for record in records:
        expected = [(record.path, record.sha256)] + [
            (o["path"], o["sha256"]) for o in record.extra.get("other_files", [])
        ]
        if any(sha256_file(session_dir / p) != h for p, h in expected):
            bad.append(record)
    if not bad:
        return records
    manifest = session_dir / MANIFEST_FILE
    (session_dir / QUARANTINE_DIR).mkdir(exist_ok=True)
    stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y%m%dT%H%M%S")
    # two resumes within a second keep both backups
    shutil.copy2(manifest, _free_name(session_dir / QUARANTINE_DIR / f"manifest-{stamp}.jsonl"))
    for record in bad:
        for path in record_paths(record):
            file = session_dir / path
            quarantine(session_dir, file, "its sha256 differs from the manifest", warn)
    keep = [r for r in records if r not in bad]
    _rewrite_manifest(session_dir, keep)
    return keep


def _classify(file: Path, frames: Iterable[FrameSpec]) -> Orphan:
    """Which planned frame (and which of its files) a raw/ file is named after, if any."""
    by_stem = {frame_name(s, ""): s for s in frames}
    stem = file.name[: -len(file.suffix)] if file.suffix else file.name
    if stem in by_stem:
        return Orphan(file, by_stem[stem], 0)
    head, _, tail = stem.rpartition("_")
    if tail.isdigit() and int(tail) > 0 and head in by_stem:
        return Orphan(file, by_stem[head], int(tail))
    return Orphan(file, None, 0)


def _adopt(
    session_dir: Path,
    orphans: list[Orphan],
    done: set[int],
    records: list[FrameRecord],
    warn: Warn,
) -> list[FrameRecord]:
    """Re-adopt orphans that verify (manifest line appended) and quarantine the rest."""
    groups: dict[int, list[Orphan]] = {}
    for orphan in orphans:
        if orphan.spec is None:
            quarantine(session_dir, orphan.path, "not named after a frame of the plan", warn)
        elif orphan.spec.frame in done:
            quarantine(session_dir, orphan.path, f"frame {orphan.spec.frame} is recorded", warn)
        else:
            groups.setdefault(orphan.spec.frame, []).append(orphan)
    adopted: list[FrameRecord] = []
    for frame in sorted(groups):
        group = sorted(groups[frame], key=lambda o: o.index)
        try:
            record = _readopt(session_dir, group, records)
        except RigError as exc:
            for orphan in group:
                quarantine(session_dir, orphan.path, exc.problem, warn)
            continue
        append_manifest(session_dir, record)
        adopted.append(record)
        warn(f"{record.path}: re-adopted as frame {frame} (it decodes; manifest line restored)")
    return adopted


def _readopt(session_dir: Path, group: list[Orphan], records: list[FrameRecord]) -> FrameRecord:
    """The manifest line of an orphaned frame: decodes, hashed now, exposure and ISO from the
    file's EXIF or else from the session's other frames (when they all agree)."""
    main = group[0]
    spec = main.spec
    assert spec is not None
    if main.index != 0:
        raise RigError(f"companion of frame {spec.frame} without its main file")
    verify_file(main.path)
    from drivers.cameras.exif import read_exif

    exif = read_exif(main.path)
    settings = {(r.exposure_s, r.iso) for r in records}
    exposure, iso = exif.exposure_s, exif.iso
    if (exposure is None or iso is None) and len(settings) == 1:
        fallback = next(iter(settings))
        exposure = exposure if exposure is not None else fallback[0]
        iso = iso if iso is not None else fallback[1]
    if exposure is None or iso is None:
        raise RigError("its exposure/ISO is neither in the file nor in the manifest")
    taken = exif.taken or dt.datetime.fromtimestamp(main.path.stat().st_mtime, dt.timezone.utc)
    extra: dict[str, object] = {
        "kind": spec.kind,
        "camera_serial": exif.serial or "",
        "readopted": True,
    }
    if spec.placement is not None:
        extra["projector_placement"] = spec.placement
    if len(group) > 1:
        extra["other_files"] = [
            {"path": _rel(session_dir, o.path), "sha256": sha256_file(o.path)} for o in group[1:]
        ]
    return FrameRecord(
        frame=spec.frame,
        view=spec.view,
        illumination=spec.label,
        path=_rel(session_dir, main.path),
        sha256=sha256_file(main.path),
        exposure_s=float(exposure),
        iso=float(iso),
        timestamp=taken.isoformat(timespec="seconds"),
        extra=extra,
    )


def _rel(session_dir: Path, path: Path) -> str:
    return path.relative_to(session_dir).as_posix()


def _truncate_torn_line(path: Path) -> None:
    """Cut the bytes after the last newline (a kill mid-append); the frame they described
    is then an orphan and is re-adopted."""
    if not path.is_file():
        return
    data = path.read_bytes()
    if not data or data.endswith(b"\n"):
        return
    with open(path, "rb+") as handle:
        handle.truncate(data.rfind(b"\n") + 1)
        handle.flush()
        os.fsync(handle.fileno())
    fsync_dir(path.parent)
