"""A minimal but valid Bayer DNG 1.4 writer (tifffile + the DNG / TIFF-EP tags).

The simulated camera writes the same kind of file a real camera (or Adobe's converter) would, so
the decode stage reads sim and real captures through the same LibRaw path. The raw mosaic is the
main image in IFD0 (NewSubFileType 0, PhotometricInterpretation 32803 = CFA, uncompressed 16-bit).
Exposure time and ISO are stored as the TIFF-EP/EXIF tags 33434 and 34855.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import tifffile

from core.errors import RigError
from core.files import atomic_output

# TIFF field types
_BYTE, _ASCII, _SHORT, _LONG, _RATIONAL, _SRATIONAL = 1, 2, 3, 4, 5, 10

CFA_COLOURS = {"R": 0, "G": 1, "B": 2}
"""DNG CFAPattern codes (CFAPlaneColor order R, G, B)."""


def _rational(x: float, signed: bool = False) -> tuple[int, int]:
    f = Fraction(float(x)).limit_denominator(1_000_000)
    if not signed and f < 0:
        raise RigError(f"DNG rational {x} must be non-negative")
    return f.numerator, f.denominator


def _flat_rationals(values: np.ndarray, signed: bool = False) -> tuple[int, ...]:
    return tuple(v for x in np.ravel(values) for v in _rational(float(x), signed))


def write_dng(
    path: Path,
    mosaic: np.ndarray,
    *,
    pattern: str = "RGGB",
    black_level: int,
    white_level: int,
    exposure_s: float,
    iso: float,
    make: str,
    model: str,
    serial: str,
    color_matrix: np.ndarray,
    as_shot_neutral: np.ndarray,
) -> None:
    """Write ``mosaic`` (H, W) uint16 Bayer data as a DNG at ``path``.

    ``color_matrix`` is DNG ColorMatrix1 (XYZ -> camera, D65 calibration illuminant) and
    ``as_shot_neutral`` the camera RGB of a neutral under the shot's light; LibRaw ignores both
    when asked for raw camera RGB, but other raw converters need them to show sensible colours.
    """
    data = np.asarray(mosaic)
    pat = pattern.upper()
    if data.dtype != np.uint16 or data.ndim != 2 or data.shape[0] % 2 or data.shape[1] % 2:
        raise RigError(
            f"DNG mosaic must be an even-sized 2-D uint16 array, got {data.dtype} {data.shape}",
            "pass the Bayer mosaic as uint16 with even width and height",
        )
    if len(pat) != 4 or set(pat) - set(CFA_COLOURS):
        raise RigError(f"CFA pattern {pattern!r} is not a 2x2 Bayer pattern", "use e.g. RGGB")
    unique_model = f"{make} {model}"
    extratags = [
        (50706, _BYTE, 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, _BYTE, 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, _ASCII, 0, unique_model, True),  # UniqueCameraModel
        (271, _ASCII, 0, make, True),  # Make
        (272, _ASCII, 0, model, True),  # Model
        (50735, _ASCII, 0, serial, True),  # CameraSerialNumber
        (33421, _SHORT, 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, _BYTE, 4, tuple(CFA_COLOURS[c] for c in pat), True),  # CFAPattern
        (50710, _BYTE, 3, (0, 1, 2), True),  # CFAPlaneColor
        (50711, _SHORT, 1, 1, True),  # CFALayout: rectangular
        (50714, _LONG, 1, int(black_level), True),  # BlackLevel
        (50717, _LONG, 1, int(white_level), True),  # WhiteLevel
        (50721, _SRATIONAL, 9, _flat_rationals(color_matrix, signed=True), True),
        (50778, _SHORT, 1, 21, True),  # CalibrationIlluminant1 = D65
        (50728, _RATIONAL, 3, _flat_rationals(as_shot_neutral), True),  # AsShotNeutral
        (33434, _RATIONAL, 1, _rational(exposure_s), True),  # ExposureTime
        (34855, _SHORT, 1, int(round(iso)), True),  # ISOSpeedRatings
    ]
    with atomic_output(path) as tmp:  # a full disk leaves no truncated frame
        tifffile.imwrite(
            tmp,
            data,
            photometric=tifffile.PHOTOMETRIC.CFA,
            compression=None,
            subfiletype=0,
            software="spectral-rig sim",
            metadata=None,
            extratags=extratags,
        )
