"""Just enough EXIF to label a frame: capture time, exposure, ISO, camera serial.

Most RAW formats (CR2, NEF, ARW, DNG, PEF, ORF...) are TIFF containers, read with tifffile;
JPEGs with Pillow. Missing or zero fields come back as None, never a guess.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ExifInfo:
    taken: datetime | None = None  # time zone aware
    exposure_s: float | None = None
    iso: float | None = None
    serial: str | None = None
    model: str | None = None


def _ratio(value: Any) -> float | None:
    if isinstance(value, tuple) and len(value) == 2:
        num, den = value
        return float(num) / float(den) if den and num else None
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number or None


def _time(text: Any, subsec: Any = "", offset: Any = "") -> datetime | None:
    """EXIF ``YYYY:MM:DD HH:MM:SS`` as an aware datetime: with the EXIF offset when the camera
    wrote one, else in this computer's time zone (where camera clocks are normally set)."""
    text = str(text or "").strip().strip("\x00")
    if not text:
        return None
    try:
        taken = datetime.strptime(text, "%Y:%m:%d %H:%M:%S")
    except ValueError:
        return None
    digits = "".join(ch for ch in str(subsec or "") if ch.isdigit())
    if digits:
        taken = taken.replace(microsecond=int((digits + "000000")[:6]))
    try:
        zone = datetime.strptime(str(offset or "").strip().strip("\x00"), "%z").tzinfo
    except ValueError:
        return taken.astimezone()
    return taken.replace(tzinfo=zone)


def _text(value: Any) -> str | None:
    text = str(value or "").strip().strip("\x00")
    return text or None


def read_exif(path: Path) -> ExifInfo:
    """EXIF of a RAW/TIFF/JPEG file; an empty ExifInfo when it has none or can't be read."""
    try:
        if path.suffix.lower() in {".jpg", ".jpeg"}:
            return _read_jpeg(path)
        return _read_tiff(path)
    except Exception as error:  # unreadable metadata must never stop an import
        log.debug("no EXIF from %s: %s", path, error)
        return ExifInfo()


def _read_tiff(path: Path) -> ExifInfo:
    import tifffile

    with tifffile.TiffFile(path) as tif:
        tags = tif.pages[0].tags
        exif = dict(tags["ExifTag"].value) if "ExifTag" in tags else {}

        def get(name: str) -> Any:
            return tags[name].value if name in tags else None

        # TIFF/EP (and DNGs written that way) may keep exposure and ISO in IFD0 itself
        iso = (
            exif.get("ISOSpeedRatings")
            or exif.get("PhotographicSensitivity")
            or get("ISOSpeedRatings")
        )
        if isinstance(iso, tuple):
            iso = iso[0] if iso else None
        return ExifInfo(
            taken=_time(
                exif.get("DateTimeOriginal"),
                exif.get("SubsecTimeOriginal"),
                exif.get("OffsetTimeOriginal"),
            )
            or _time(get("DateTime")),
            exposure_s=_ratio(exif.get("ExposureTime") or get("ExposureTime")),
            iso=float(iso) if iso else None,
            serial=_text(exif.get("BodySerialNumber") or get("CameraSerialNumber")),
            model=_text(get("Model")),
        )


def _read_jpeg(path: Path) -> ExifInfo:
    from PIL import Image

    with Image.open(path) as image:
        base = image.getexif()
        exif = base.get_ifd(0x8769)
        iso = exif.get(0x8827)
        return ExifInfo(
            taken=_time(exif.get(0x9003), exif.get(0x9291), exif.get(0x9011))
            or _time(base.get(0x0132)),
            exposure_s=_ratio(exif.get(0x829A)),
            iso=float(iso) if iso else None,
            serial=_text(exif.get(0xA431)),
            model=_text(base.get(0x0110)),
        )
