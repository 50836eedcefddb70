"""Just enough EXIF to label a frame: capture time, exposure, ISO, camera serial.

Read with exifread, one path for TIFF-based RAWs (CR2, NEF, ARW, DNG, PEF, ORF, RW2...),
JPEG, HEIC and PNG. Missing or zero fields come back as None, never a guess.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import exifread

log = logging.getLogger(__name__)
# exifread warns, without the file's name, about every file it finds no EXIF in; read_exif
# says which file itself
logging.getLogger("exifread").setLevel(logging.ERROR)

# exifread names no DNG tag: CameraSerialNumber (0xC62F) keeps its number in the key
DNG_CAMERA_SERIAL = "Image Tag 0xC62F"


@dataclass(frozen=True)
class ExifInfo:
    taken: datetime | None = None  # time zone aware
    exposure_s: float | None = None
    iso: float | None = None
    serial: str | None = None
    model: str | None = None


def _value(tags: dict[str, Any], *names: str) -> Any:
    """The first named tag holding a non-empty, non-zero value (a list's first item)."""
    for name in names:
        values = getattr(tags.get(name), "values", None)
        if isinstance(values, list):
            values = values[0] if values else None
        if isinstance(values, tuple):  # exifread keeps FLOAT/DOUBLE values as 1-tuples
            values = values[0] if values else None
        if isinstance(values, str):
            values = values.strip().strip("\x00")
        if values:
            return values
    return None


def _number(value: Any) -> float | None:
    try:
        return float(value) or None
    except (TypeError, ValueError, ZeroDivisionError):
        return None


def _time(text: Any, subsec: Any = None, offset: Any = None) -> datetime | None:
    """EXIF ``YYYY:MM:DD HH:MM:SS`` as an aware datetime: with the EXIF offset when the camera
    wrote one, else in this computer's time zone (where camera clocks are normally set)."""
    try:
        taken = datetime.strptime(str(text or ""), "%Y:%m:%d %H:%M:%S")
    except ValueError:
        return None
    digits = "".join(ch for ch in str(subsec or "") if ch.isdigit())
    if digits:
        taken = taken.replace(microsecond=int((digits + "000000")[:6]))
    try:
        zone = datetime.strptime(str(offset or ""), "%z").tzinfo
    except ValueError:
        return taken.astimezone()
    return taken.replace(tzinfo=zone)


def read_exif(path: Path) -> ExifInfo:
    """EXIF of a RAW/TIFF/JPEG file; an empty ExifInfo when it has none or can't be read."""
    try:
        with path.open("rb") as file:
            tags = exifread.process_file(file, details=False, extract_thumbnail=False)
    except Exception as error:  # unreadable metadata must never stop an import
        log.debug("no EXIF from %s: %s", path, error)
        return ExifInfo()
    if not tags:
        log.debug("no EXIF in %s", path)
    # TIFF/EP (and DNGs written that way) may keep exposure and ISO in IFD0 itself
    serial = _value(tags, "EXIF BodySerialNumber", DNG_CAMERA_SERIAL)
    model = _value(tags, "Image Model")
    return ExifInfo(
        taken=_time(
            _value(tags, "EXIF DateTimeOriginal"),
            _value(tags, "EXIF SubSecTimeOriginal"),
            _value(tags, "EXIF OffsetTimeOriginal"),
        )
        or _time(_value(tags, "Image DateTime")),
        exposure_s=_number(_value(tags, "EXIF ExposureTime", "Image ExposureTime")),
        iso=_number(_value(tags, "EXIF ISOSpeedRatings", "Image ISOSpeedRatings")),
        serial=str(serial) if serial else None,
        model=str(model) if model else None,
    )
