"""Cameras whose vendor tethering app (EOS Utility, Nikon Camera Control, Capture One...)
drops each shot into a folder: wait for a new file, and for it to be complete (its size
stops changing), then move it into the session.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from core.errors import RigError
from drivers.cameras.exif import read_exif
from drivers.cameras.files import copy_durably, target_path
from drivers.protocols import CapturedFrame

RAW_EXTENSIONS = (
    ".cr2", ".cr3", ".nef", ".nrw", ".arw", ".dng", ".raf", ".orf", ".rw2", ".pef", ".srw",
    ".tif", ".tiff",
)  # fmt: skip


def list_files(folder: Path, extensions: Iterable[str]) -> dict[Path, int]:
    wanted = {e.lower() for e in extensions}
    return {
        p: p.stat().st_size
        for p in folder.iterdir()
        if p.is_file() and p.suffix.lower() in wanted and not p.name.startswith(".")
    }


def frame_from_files(
    paths: list[Path], default_exposure_s: float | None, default_iso: float | None, serial: str
) -> CapturedFrame:
    """Metadata from the first file's EXIF, else the profile's defaults."""
    exif = read_exif(paths[0])
    exposure = exif.exposure_s or default_exposure_s
    iso = exif.iso or default_iso
    if exposure is None or iso is None:
        raise RigError(
            f"{paths[0].name} carries no exposure time/ISO in its EXIF",
            "give `exposure_s:` and `iso:` in the camera section of the profile",
        )
    taken = (exif.taken or datetime.now(timezone.utc)).astimezone(timezone.utc).isoformat()
    return CapturedFrame(
        paths=tuple(paths),
        exposure_s=exposure,
        iso=iso,
        camera_serial=exif.serial or serial,
        timestamp=taken,
        extra={"model": exif.model} if exif.model else {},
    )


class FolderWatchCamera:
    driver_name = "folder-watch"

    def __init__(
        self,
        folder: str | Path,
        trigger: Callable[[str], Any] | None = None,
        extensions: Iterable[str] = RAW_EXTENSIONS,
        timeout_s: float = 120.0,
        stable_s: float = 1.0,
        poll_s: float = 0.25,
        move: bool = True,
        exposure_s: float | None = None,
        iso: float | None = None,
        serial: str = "unknown",
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise RigError(
                f"watch folder {self.folder} does not exist",
                "create it and point the tethering app's download folder at it",
            )
        self.trigger = trigger or (lambda stem: input(f"Take shot {stem} now, then press Enter: "))
        self.extensions = tuple(extensions)
        self.timeout_s, self.stable_s, self.poll_s = timeout_s, stable_s, poll_s
        self.move = move
        self.default_exposure_s, self.default_iso, self.serial = exposure_s, iso, serial
        self._clock, self._sleep = clock, sleep

    def capture(self, out_dir: Path, stem: str) -> CapturedFrame:
        before = set(list_files(self.folder, self.extensions))
        self.trigger(stem)
        deadline = self._clock() + self.timeout_s
        sizes: dict[Path, int] = {}
        stable_since: float | None = None
        while True:
            now = self._clock()
            current = {
                p: s for p, s in list_files(self.folder, self.extensions).items() if p not in before
            }
            if current and current == sizes and all(s > 0 for s in current.values()):
                stable_since = stable_since if stable_since is not None else now
                if now - stable_since >= self.stable_s:
                    break
            else:
                stable_since = None
            sizes = current
            if now > deadline:
                raise RigError(
                    f"no complete new file appeared in {self.folder} within {self.timeout_s:g} s",
                    "check the tethering app saves into that folder and the shot was taken",
                )
            self._sleep(self.poll_s)
        out_dir.mkdir(parents=True, exist_ok=True)
        taken: set[Path] = set()
        paths = []
        for source in sorted(sizes):
            path = target_path(out_dir, stem, source.suffix, taken)
            copy_durably(source, path, move=self.move)
            paths.append(path)
        return frame_from_files(paths, self.default_exposure_s, self.default_iso, self.serial)

    def describe(self) -> dict[str, Any]:
        return {"kind": "camera", "driver": self.driver_name, "folder": str(self.folder)}

    def close(self) -> None:
        return None
