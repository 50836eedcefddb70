"""A flat field from lensfun's vignetting profile of a known camera and lens (``lensfunpy``,
the optional extra ``lensfun``).

lensfun's reverse colour modification applied to an image of ones gives the lens's gain map
(the fall-off it puts on a uniform scene); it is refitted to :mod:`calibration.flat_field`'s
model, which is lensfun's own polynomial, so the fit is exact up to rounding.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration.flat_field import FlatField, fit_flat_field
from core.errors import MissingDependencyError, RigError

FIT_SIDE_PX = 600  # the map is fitted at this width: the model is smooth, the size irrelevant


def _lensfunpy() -> Any:
    try:
        import lensfunpy
    except ImportError as error:
        raise MissingDependencyError(
            "lensfunpy", "lensfun", "needed for a flat field from a lensfun profile"
        ) from error
    return lensfunpy


def lensfun_flat_field(
    camera: str,
    lens: str,
    focal_mm: float,
    aperture: float,
    size: tuple[int, int],
    distance_m: float = 1000.0,
) -> FlatField:
    """The flat field of ``lens`` on ``camera`` ("MAKER MODEL" as in lensfun's database, e.g.
    "Canon Canon EOS 5D Mark II") at ``focal_mm`` and f/``aperture``, for images of
    ``size`` (width, height)."""
    lensfunpy = _lensfunpy()
    db = lensfunpy.Database()
    maker, _, model = camera.partition(" ")
    cameras = db.find_cameras(maker, model) if model else []
    if not cameras:
        raise RigError(
            f"lensfun has no camera {camera!r}",
            "write the maker then the model as lensfun spells them, e.g. "
            "'Canon Canon EOS 5D Mark II' (see https://lensfun.github.io/lenslist/)",
        )
    cam = cameras[0]
    lenses = db.find_lenses(cam, None, lens)
    if not lenses:
        raise RigError(
            f"lensfun has no lens {lens!r} for {cam.maker} {cam.model}",
            "write the lens model as lensfun spells it, e.g. 'Canon EF 50mm f/1.4 USM'",
        )
    found = lenses[0]
    if not found.min_focal - 1e-6 <= focal_mm <= found.max_focal + 1e-6:
        raise RigError(
            f"--focal {focal_mm:g} mm is outside {found.model}'s "
            f"{found.min_focal:g}–{found.max_focal:g} mm",
            "give the focal length the frames were taken at",
        )
    width, height = size
    fit_w = min(width, FIT_SIDE_PX)
    fit_h = max(2, round(fit_w * height / width))
    modifier = lensfunpy.Modifier(found, cam.crop_factor, fit_w, fit_h)
    # reverse: the fall-off the lens adds to a uniform scene, not its correction
    modifier.initialize(
        focal_mm,
        aperture,
        distance_m,
        pixel_format=np.float32,
        flags=lensfunpy.ModifyFlags.VIGNETTING,
        reverse=True,
    )
    image = np.ones((fit_h, fit_w, 3), np.float32)
    if not modifier.apply_color_modification(image):
        raise RigError(
            f"lensfun has no vignetting data for {found.model} at {focal_mm:g} mm f/{aperture:g}",
            "photograph a white card instead (`rig calibrate flat-field RAW... --camera NAME`)",
        )
    details = {
        "lensfun_camera": str(cam.model),
        "lensfun_lens": str(found.model),
        "focal_mm": float(focal_mm),
        "aperture": float(aperture),
        "lensfunpy": str(lensfunpy.__version__),
    }
    flat = fit_flat_field([image.astype(float)], method="lensfun", details=details)
    return FlatField(flat.coefficients, width / height, flat.centre, flat.method, flat.details)
