"""One frame from camera to manifest: verify it decodes, hash it, make it durable under its
final name, then append its manifest line. Plus the exposure check on first frames."""

from __future__ import annotations

import os
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from core.errors import RigError
from core.files import fsync_dir, sha256_file
from core.manifest import FrameRecord, append_manifest
from core.session import RAW_DIR
from drivers.protocols import CapturedFrame
from rig.plans import FrameSpec

INCOMING = ".incoming"  # under raw/: where the camera writes; leftovers go to quarantine/
TIFF_SUFFIXES = (".tif", ".tiff")
NPY_SUFFIXES = (".npy",)
SATURATED_LIMIT = 0.005  # fraction of lit pixels saturated that triggers "shorten the exposure"
SATURATED_LEVEL = 0.998  # of full scale: a pixel at or above it is clipped
DARK_P99 = 0.10  # lit pixels' 99th percentile below this fraction of full scale: "lengthen"
LIT_FLOOR = 0.02  # of full scale: above it a pixel is lit (object, board), below it background
MIN_LIT_FRACTION = 0.001  # fewer lit pixels (hot pixels, a glint): judge the whole frame
SAMPLE_PIXELS = 1_000_000  # the exposure check looks at about this many pixels


@dataclass(frozen=True)
class RawData:
    """Sensor values with their black and white levels (enough for the exposure check); for
    a colour-filter mosaic also each filter position's black level and white-balance gain
    (``cfa_black``, ``cfa_gain``: one CFA period, e.g. 2x2), so the board check can build its
    grey look from the mosaic already decoded instead of demosaicing the file again."""

    values: np.ndarray
    black: float
    white: float
    cfa_black: np.ndarray | None = None
    cfa_gain: np.ndarray | None = None

    @property
    def period(self) -> int:
        """Rows/columns of one CFA period (1 for demosaiced or monochrome data)."""
        return 1 if self.cfa_gain is None else int(self.cfa_gain.shape[0])


def read_raw(path: Path) -> RawData:
    """Decode a frame file: RAW via :mod:`reconstruct.frames.raw`, linear TIFF via tifffile,
    NumPy arrays. Raises RigError naming the file when it does not decode."""
    suffix = path.suffix.lower()
    try:
        if suffix in TIFF_SUFFIXES:
            import tifffile

            values = np.asarray(tifffile.imread(path))
            return RawData(values, 0.0, _full_scale(values))
        if suffix in NPY_SUFFIXES:
            values = np.load(path, allow_pickle=False)
            return RawData(values, 0.0, _full_scale(values))
        from reconstruct.frames.raw import read_mosaic

        mosaic = read_mosaic(path)
        cfa: tuple[np.ndarray | None, np.ndarray | None] = (None, None)
        if mosaic.pattern is not None and mosaic.values.ndim == 2:
            cfa = _cfa_levels(mosaic.pattern, mosaic.channel_black, mosaic.camera_wb, mosaic.white)
        return RawData(mosaic.values, mosaic.mean_black, mosaic.white, *cfa)
    except RigError:
        raise
    except Exception as exc:
        raise RigError(
            f"frame file {path} does not decode ({type(exc).__name__}: {exc})",
            "check the camera's RAW format setting and the USB cable; "
            "the frame will be captured again",
        ) from exc


def _cfa_levels(
    colours: np.ndarray, channel_black: np.ndarray, wb: np.ndarray, white: float
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Per CFA position: black level and gain to white-balanced [0, 1] (as LibRaw scales with
    the camera's white balance: multipliers normalised to a smallest of 1). None when the
    data is no square mosaic."""
    if colours.ndim != 2 or colours.shape[0] != colours.shape[1] or colours.shape[0] < 2:
        return None, None
    wb = wb.copy()
    if wb.size > 3 and wb[3] <= 0:  # RGBG sensors: the second green takes the first's gain
        wb[3] = wb[1]
    wb = wb / wb[wb > 0].min() if np.any(wb > 0) else np.ones_like(wb)
    wb[wb <= 0] = 1.0
    black = channel_black[colours]
    return black, wb[colours] / np.maximum(white - black, 1e-12)


def _full_scale(values: np.ndarray) -> float:
    if np.issubdtype(values.dtype, np.integer):
        return float(np.iinfo(values.dtype).max)
    return 1.0


def verify_file(path: Path) -> RawData:
    """Exists, non-empty, decodes; the decoded data (the checks after it reuse it)."""
    if not path.is_file():
        raise RigError(
            f"the camera reported {path} but it is not on disk",
            "check the download folder and free disk space",
        )
    if path.stat().st_size == 0:
        raise RigError(f"frame file {path} is empty", "check free disk space and the cable")
    return read_raw(path)


@dataclass(frozen=True)
class ExposureCheck:
    """Levels of the lit region (pixels above LIT_FLOOR; the whole frame when hardly any is
    lit), relative to full scale."""

    label: str
    saturated_fraction: float  # of the lit pixels
    mean_level: float  # whole frame
    p99_level: float  # of the lit pixels
    lit_fraction: float
    exposure_s: float
    suggestion: str | None

    def as_dict(self) -> dict[str, object]:
        return {
            "saturated_fraction": round(self.saturated_fraction, 6),
            "mean_level": round(self.mean_level, 6),
            "p99_level": round(self.p99_level, 6),
            "lit_fraction": round(self.lit_fraction, 6),
            "exposure_s": self.exposure_s,
            "suggestion": self.suggestion,
        }


def exposure_sample(raw: RawData) -> np.ndarray:
    """Levels (black 0, white 1) of whole CFA periods on a regular grid, about SAMPLE_PIXELS
    of them: a 21 MP frame costs what a 1 MP one does and every colour keeps its share."""
    h, w = raw.values.shape[:2]
    period = max(raw.period, 1)
    step = max(1, int(np.ceil(np.sqrt(h * w / SAMPLE_PIXELS))))  # keep one period in step
    rows = np.flatnonzero((np.arange(h) // period) % step == 0)
    cols = np.flatnonzero((np.arange(w) // period) % step == 0)
    sample = raw.values[np.ix_(rows, cols)] if step > 1 else raw.values
    span = max(raw.white - raw.black, 1e-12)
    return ((sample.astype(np.float32) - np.float32(raw.black)) / np.float32(span)).ravel()


def check_exposure(raw: RawData, label: str, exposure_s: float) -> ExposureCheck:
    """Judge the lit region, not the whole frame: a small object on a black background is
    well exposed when the object is, however dark the rest. Saturated fraction and 99th
    percentile of the pixels above LIT_FLOOR, with a concrete suggestion."""
    level = exposure_sample(raw)
    lit = level[level > LIT_FLOOR]
    lit_fraction = lit.size / max(level.size, 1)
    judged = lit if lit_fraction >= MIN_LIT_FRACTION else level  # hot pixels are no object
    saturated = float(np.mean(judged >= SATURATED_LEVEL))
    p99 = float(np.percentile(judged, 99.0))
    suggestion = None
    if saturated > SATURATED_LIMIT:
        factor = 0.5 if saturated < 0.05 else 0.25
        word = "halve" if factor == 0.5 else "quarter"
        suggestion = (
            f"{label}: {100 * saturated:.1f} % of the lit pixels saturated — {word} the "
            f"exposure to {format_shutter(exposure_s * factor)}"
        )
    elif p99 < DARK_P99:
        stops = int(np.clip(np.floor(np.log2(0.8 / max(p99, 1e-6))), 1, 6))
        where = (
            f"99 % of the lit pixels below {100 * p99:.0f} % of full scale"
            if judged is lit
            else f"nothing above {100 * LIT_FLOOR:.0f} % of full scale"
        )
        suggestion = (
            f"{label}: underexposed ({where}) — lengthen the exposure {stops} "
            f"stop{'s' * (stops > 1)} to {format_shutter(exposure_s * 2**stops)}"
        )
    return ExposureCheck(
        label, saturated, float(level.mean()), p99, lit_fraction, exposure_s, suggestion
    )


def format_shutter(seconds: float) -> str:
    """Shutter speeds as cameras show them: ``1/60 s`` below half a second."""
    if seconds < 0.5:
        return f"1/{Fraction(1 / seconds).limit_denominator(1).numerator} s"
    return f"{seconds:.3g} s"


def frame_name(spec: FrameSpec, suffix: str, index: int = 0) -> str:
    extra = f"_{index}" if index else ""
    return f"v{spec.view:03d}_f{spec.frame:05d}_{spec.label}{extra}{suffix.lower()}"


def store_frame(
    session_dir: Path, spec: FrameSpec, captured: CapturedFrame
) -> tuple[FrameRecord, RawData]:
    """Verify, fsync and rename the camera's file(s) into raw/, then append the manifest line.
    Returns the record and the main file's decoded data (for the checks that follow).

    The manifest line is written last: a kill before it leaves an orphan file (re-adopted on
    resume when it verifies, else moved to quarantine/ and captured again: never deleted), a
    kill after it leaves a complete frame — never a half one."""
    if not captured.paths:
        raise RigError(
            f"the camera delivered no file for frame {spec.frame}",
            "check the camera's capture target (memory card vs. computer)",
        )
    raw_dir = session_dir / RAW_DIR
    stored: list[tuple[str, str]] = []
    main: RawData | None = None
    for index, source in enumerate(captured.paths):
        source = Path(source)
        data = verify_file(source)
        if main is None:
            main = data
        _fsync_file(source)
        final = raw_dir / frame_name(spec, source.suffix, index)
        os.replace(source, final)
        stored.append((final.relative_to(session_dir).as_posix(), sha256_file(final)))
    fsync_dir(raw_dir)
    extra: dict[str, object] = {
        "kind": spec.kind,
        "camera_serial": captured.camera_serial,
        **dict(captured.extra),
    }
    if spec.placement is not None:  # reconstruct.initial_mesh.procam groups views by it
        extra["projector_placement"] = spec.placement
    if len(stored) > 1:
        extra["other_files"] = [{"path": p, "sha256": h} for p, h in stored[1:]]
    record = FrameRecord(
        frame=spec.frame,
        view=spec.view,
        illumination=spec.label,
        path=stored[0][0],
        sha256=stored[0][1],
        exposure_s=float(captured.exposure_s),
        iso=float(captured.iso),
        timestamp=captured.timestamp,
        extra=extra,
    )
    append_manifest(session_dir, record)
    assert main is not None
    return record, main


def _fsync_file(path: Path) -> None:
    with open(path, "rb+") as handle:
        os.fsync(handle.fileno())
