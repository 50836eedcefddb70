"""Frames shot without tethering (hand-held, any camera): import the files afterwards and
match them to the capture plan's frames by capture order (EXIF time, then name).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from core.errors import RigError
from drivers.cameras.exif import read_exif
from drivers.cameras.files import copy_durably, target_path
from drivers.cameras.folder_watch import RAW_EXTENSIONS, frame_from_files, list_files
from drivers.protocols import CapturedFrame


def capture_order(paths: Iterable[Path]) -> list[Path]:
    """Sort by EXIF capture time (sub-second when present); files without it by modification
    time; ties by name (burst shots within one second)."""

    def key(path: Path) -> tuple[datetime, str]:
        taken = read_exif(path).taken or datetime.fromtimestamp(path.stat().st_mtime, timezone.utc)
        return taken, path.name

    return sorted(paths, key=key)


def match_files_to_frames(paths: Sequence[Path], frame_count: int) -> list[Path]:
    """The files in capture order, one per frame; a count mismatch is an error, not a guess."""
    ordered = capture_order(paths)
    if len(ordered) != frame_count:
        raise RigError(
            f"found {len(ordered)} image files but the capture plan has {frame_count} frames",
            "remove extra shots (test shots, duplicates) or re-shoot the missing ones",
        )
    return ordered


class HandheldImportCamera:
    """A ``Camera`` whose n-th capture is the n-th existing file in capture order (copied;
    the originals are never modified)."""

    driver_name = "handheld-import"

    def __init__(
        self,
        folder: str | Path,
        extensions: Iterable[str] = RAW_EXTENSIONS,
        frame_count: int | None = None,
        exposure_s: float | None = None,
        iso: float | None = None,
        serial: str = "unknown",
    ) -> None:
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise RigError(
                f"import folder {self.folder} does not exist", "give the folder with the shots"
            )
        extensions = tuple(extensions)  # read twice: for the listing and the error message
        files = list(list_files(self.folder, extensions))
        self.files = (
            match_files_to_frames(files, frame_count)
            if frame_count is not None
            else capture_order(files)
        )
        if not self.files:
            raise RigError(
                f"no image files in {self.folder}", f"expected one of {', '.join(extensions)}"
            )
        self.position = 0
        self.default_exposure_s, self.default_iso, self.serial = exposure_s, iso, serial

    def capture(self, out_dir: Path, stem: str) -> CapturedFrame:
        if self.position >= len(self.files):
            raise RigError(
                f"all {len(self.files)} files in {self.folder} are used; another frame is needed",
                "add the missing shots to the folder and resume",
            )
        source = self.files[self.position]
        out_dir.mkdir(parents=True, exist_ok=True)
        path = target_path(out_dir, stem, source.suffix, set())
        copy_durably(source, path)
        self.position += 1
        frame = frame_from_files([path], self.default_exposure_s, self.default_iso, self.serial)
        return replace(frame, extra={**frame.extra, "source": str(source)})

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "camera",
            "driver": self.driver_name,
            "folder": str(self.folder),
            "files": len(self.files),
        }

    def close(self) -> None:
        return None
