"""One frame from camera to manifest: verify it decodes, hash it, make it durable under its
final name, then append its manifest line. Plus the exposure check on first frames."""

from __future__ import annotations

import os
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from calibration.errors import RigError
from drivers.protocols import CapturedFrame
from reconstruct.session import (
    RAW_DIR,
    FrameRecord,
    append_manifest,
    fsync_dir,
    sha256_file,
)
from rig.plans import FrameSpec

INCOMING = ".incoming"  # under raw/: where the camera writes; anything left there is discarded
TIFF_SUFFIXES = (".tif", ".tiff")
NPY_SUFFIXES = (".npy",)
SATURATED_LIMIT = 0.005  # fraction of saturated pixels that triggers "shorten the exposure"
DARK_P99 = 0.10  # 99th percentile below this fraction of full scale: "lengthen the exposure"


@dataclass(frozen=True)
class RawData:
    """Sensor values with their black and white levels (enough for the exposure check)."""

    values: np.ndarray
    black: float
    white: float


def read_raw(path: Path) -> RawData:
    """Decode a frame file: RAW via LibRaw (rawpy), linear TIFF via tifffile, NumPy arrays.
    Raises RigError naming the file when it does not decode."""
    suffix = path.suffix.lower()
    try:
        if suffix in TIFF_SUFFIXES:
            import tifffile

            values = np.asarray(tifffile.imread(path))
            return RawData(values, 0.0, _full_scale(values))
        if suffix in NPY_SUFFIXES:
            values = np.load(path, allow_pickle=False)
            return RawData(values, 0.0, _full_scale(values))
        import rawpy

        with rawpy.imread(str(path)) as raw:
            values = raw.raw_image_visible.copy()
            black = float(np.mean(raw.black_level_per_channel))
            white = float(raw.white_level)
        return RawData(values, black, white)
    except RigError:
        raise
    except Exception as exc:
        raise RigError(
            f"frame file {path} does not decode ({type(exc).__name__}: {exc})",
            "check the camera's RAW format setting and the USB cable; "
            "the frame will be captured again",
        ) from exc


def _full_scale(values: np.ndarray) -> float:
    if np.issubdtype(values.dtype, np.integer):
        return float(np.iinfo(values.dtype).max)
    return 1.0


def verify_file(path: Path) -> None:
    """Exists, non-empty, decodes."""
    if not path.is_file():
        raise RigError(
            f"the camera reported {path} but it is not on disk",
            "check the download folder and free disk space",
        )
    if path.stat().st_size == 0:
        raise RigError(f"frame file {path} is empty", "check free disk space and the cable")
    read_raw(path)


@dataclass(frozen=True)
class ExposureCheck:
    label: str
    saturated_fraction: float
    mean_level: float
    p99_level: float
    exposure_s: float
    suggestion: str | None

    def as_dict(self) -> dict[str, object]:
        return {
            "saturated_fraction": round(self.saturated_fraction, 6),
            "mean_level": round(self.mean_level, 6),
            "p99_level": round(self.p99_level, 6),
            "exposure_s": self.exposure_s,
            "suggestion": self.suggestion,
        }


def check_exposure(raw: RawData, label: str, exposure_s: float) -> ExposureCheck:
    """Saturated fraction and levels relative to full scale, with a concrete suggestion."""
    span = max(raw.white - raw.black, 1e-12)
    level = (raw.values.astype(np.float64) - raw.black) / span
    saturated = float(np.mean(raw.values >= raw.white - 0.002 * span))
    mean = float(level.mean())
    p99 = float(np.percentile(level, 99.0))
    suggestion = None
    if saturated > SATURATED_LIMIT:
        factor = 0.5 if saturated < 0.05 else 0.25
        word = "halve" if factor == 0.5 else "quarter"
        suggestion = (
            f"{label}: {100 * saturated:.1f} % pixels saturated — {word} the exposure "
            f"to {format_shutter(exposure_s * factor)}"
        )
    elif p99 < DARK_P99:
        stops = int(np.clip(np.floor(np.log2(0.8 / max(p99, 1e-6))), 1, 6))
        suggestion = (
            f"{label}: underexposed (99 % of pixels below {100 * p99:.0f} % of full "
            f"scale) — lengthen the exposure {stops} stop{'s' * (stops > 1)} to "
            f"{format_shutter(exposure_s * 2**stops)}"
        )
    return ExposureCheck(label, saturated, mean, p99, exposure_s, suggestion)


def board_image(path: Path) -> np.ndarray:
    """A quick 8-bit RGB look at a frame for the board check: RAW through LibRaw with
    bilinear demosaicing (half size for large sensors, camera white balance, BT.709 gamma,
    no auto-brightening, so the board's contrast tells about the exposure), linear
    TIFF/NumPy frames through :func:`reconstruct.board.linear_to_u8`."""
    from reconstruct.board import linear_to_u8

    suffix = path.suffix.lower()
    if suffix in TIFF_SUFFIXES + NPY_SUFFIXES:
        data = read_raw(path)
        span = max(data.white - data.black, 1e-12)
        return linear_to_u8((data.values.astype(np.float64) - data.black) / span)
    import rawpy

    try:
        with rawpy.imread(str(path)) as raw:
            return np.asarray(
                raw.postprocess(
                    half_size=bool(raw.sizes.width > 2000),
                    demosaic_algorithm=rawpy.DemosaicAlgorithm.LINEAR,
                    use_camera_wb=True,
                    no_auto_bright=True,
                    output_bps=8,
                )
            )
    except Exception as exc:
        raise RigError(
            f"frame file {path} does not decode for the board check ({exc})",
            "check the camera's RAW format setting",
        ) from exc


def format_shutter(seconds: float) -> str:
    """Shutter speeds as cameras show them: ``1/60 s`` below half a second."""
    if seconds < 0.5:
        return f"1/{Fraction(1 / seconds).limit_denominator(1).numerator} s"
    return f"{seconds:.3g} s"


def frame_name(spec: FrameSpec, suffix: str, index: int = 0) -> str:
    extra = f"_{index}" if index else ""
    return f"v{spec.view:03d}_f{spec.frame:05d}_{spec.label}{extra}{suffix.lower()}"


def store_frame(session_dir: Path, spec: FrameSpec, captured: CapturedFrame) -> FrameRecord:
    """Verify, fsync and rename the camera's file(s) into raw/, then append the manifest line.

    The manifest line is written last: a kill before it leaves an orphan file (deleted and
    re-captured on resume), a kill after it leaves a complete frame — never a half one."""
    if not captured.paths:
        raise RigError(
            f"the camera delivered no file for frame {spec.frame}",
            "check the camera's capture target (memory card vs. computer)",
        )
    raw_dir = session_dir / RAW_DIR
    stored: list[tuple[str, str]] = []
    for index, source in enumerate(captured.paths):
        source = Path(source)
        verify_file(source)
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
    if spec.placement is not None:  # reconstruct.procam groups views by it
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
    return record


def _fsync_file(path: Path) -> None:
    with open(path, "rb+") as handle:
        os.fsync(handle.fileno())


def record_paths(record: FrameRecord) -> list[str]:
    """Every file a manifest line owns (the main one and any companions)."""
    others = record.extra.get("other_files", [])
    return [record.path, *(o["path"] for o in others if isinstance(o, dict) and "path" in o)]
