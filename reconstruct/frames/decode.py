"""Decode stage: RAW (or linear TIFF/NPY) frames -> linear camera RGB + saturation masks.

Values follow docs/architecture.md (Linear image values):
``y = (raw - black) / (white - black) / (exposure_s * iso / 100)``, demosaiced in camera RGB with
no white balance, colour matrix or gamma (RAW files are read by :mod:`reconstruct.frames.raw`),
divided by the session's flat field when it names one (``calibration.flat_field``: the lens's
fall-off, :mod:`calibration.flat_field`). A pixel is saturated when any mosaic sample in its
demosaic neighbourhood is at or near the white level; such pixels are never used.

Outputs in ``recon/decoded/``: ``<frame>.npy`` (H x W x 3, float16, or float32 beyond its
range), ``<frame>_sat.npy`` (bool mask), ``index.json`` (frame -> view, illumination, files,
skipped frames and why), and 8-bit tone-mapped copies of one frame per view in ``sfm/`` for
structure from motion. :func:`drop_frames` deletes the frames and SfM images after a run
(the stage then decodes them again when it is next run; the index, unchanged, keeps later
stages done).
"""

from __future__ import annotations

import json
import logging
from collections import deque
from collections.abc import Iterator, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import rawpy
import tifffile
from rich.progress import track
from scipy.ndimage import maximum_filter

from calibration.flat_field import FlatField
from calibration.store import CalibrationStore
from core.config import bounded, from_mapping
from core.errors import RigError
from core.files import atomic_output, write_bytes_atomically
from core.machine import usable_cores
from core.manifest import MANIFEST_FILE, FrameRecord, verify_frames
from core.manifest_check import check_session
from core.session import Session
from reconstruct.frames.pyramid import resize_area, resize_mask
from reconstruct.frames.raw import read_linear_rgb
from reconstruct.stages.resolution import frame_level, level_size
from reconstruct.stages.resumable import STAMP, run_stage

log = logging.getLogger("reconstruct.frames.decode")

INDEX = "index.json"
SFM_DIR = "sfm"
FLOAT16_RANGE = 6e4  # largest value a frame may hold to be kept as float16 (max 65504)
LINEAR_SUFFIXES = {".npy", ".tif", ".tiff"}
DECODE_THREADS = 4  # at most; one per core below that


@dataclass(frozen=True)
class DecodeConfig:
    """``demosaic``: LibRaw algorithm; ``saturation``: fraction of (white - black) above which
    a mosaic sample counts as clipped; ``on_bad_frame``: ``skip`` or ``stop``;
    ``sfm_illumination``: which illumination's frame of each view goes to SfM (None: the
    brightest)."""

    demosaic: Literal["linear", "vng", "ppg", "ahd", "dcb", "dht", "aahd"] = "ahd"  # DEMOSAIC
    saturation: float = bounded(0.98, above=0.0, max=1.0)
    on_bad_frame: Literal["skip", "stop"] = "skip"
    sfm_illumination: str | None = None
    sfm_max_side: int = bounded(0, min=0, max=100_000)  # 0: keep the full size


@dataclass
class DecodedFrame:
    """One decoded frame as listed in ``index.json`` (paths relative to ``recon/decoded``)."""

    frame: int
    view: int
    illumination: str
    image: str
    saturated: str
    source: str
    exposure_s: float
    iso: float
    height: int
    width: int
    saturated_fraction: float
    extra: dict[str, Any] = field(default_factory=dict)
    level: int = 0  # pyramid level: the RAW frame halved this many times


@dataclass
class DecodeIndex:
    frames: list[DecodedFrame]
    skipped: dict[str, str]  # source path -> reason
    sfm_images: dict[int, str]  # view -> file name in sfm/

    @classmethod
    def load(cls, out_dir: Path) -> DecodeIndex:
        data = json.loads((out_dir / INDEX).read_text())
        return cls(
            [DecodedFrame(**f) for f in data["frames"]],
            data["skipped"],
            {int(k): v for k, v in data["sfm_images"].items()},
        )

    def save(self, out_dir: Path) -> None:
        data = {
            "frames": [asdict(f) for f in self.frames],
            "skipped": self.skipped,
            "sfm_images": {str(k): v for k, v in self.sfm_images.items()},
        }
        text = json.dumps(data, indent=1).encode()
        path = out_dir / INDEX
        # an unchanged index keeps its mtime: frames decoded again after drop_frames leave
        # the later stages, which hash it, up to date
        if not (path.is_file() and path.read_bytes() == text):
            write_bytes_atomically(path, text)


def frame_files(out_dir: Path) -> list[Path]:
    """The decoded frames, saturation masks and SfM images in ``out_dir`` that exist."""
    if not (out_dir / INDEX).is_file():
        return []
    index = DecodeIndex.load(out_dir)
    paths = [out_dir / name for f in index.frames for name in (f.image, f.saturated)]
    paths += [out_dir / SFM_DIR / name for name in index.sfm_images.values()]
    return [p for p in paths if p.is_file()]


def frame_bytes(out_dir: Path) -> int:
    """Bytes the decoded frames, saturation masks and SfM images take in ``out_dir``."""
    return sum(p.stat().st_size for p in frame_files(out_dir))


def drop_frames(out_dir: Path) -> int:
    """Delete the decoded frames, saturation masks and SfM images (the bulk of ``recon/``),
    keeping the index; returns the bytes freed. The stage's stamp goes first, so the next run
    decodes them again even if this one is cut short."""
    files = frame_files(out_dir)
    (out_dir / STAMP).unlink(missing_ok=True)
    freed = 0
    for path in files:
        freed += path.stat().st_size
        path.unlink()
    return freed


def load_frame(out_dir: Path, frame: DecodedFrame) -> tuple[np.ndarray, np.ndarray]:
    """Linear float32 image (H, W, 3) and saturation mask (H, W) of a decoded frame."""
    image = np.load(out_dir / frame.image).astype(np.float32)
    return image, np.load(out_dir / frame.saturated)


def decode_raw(path: Path, demosaic: str, saturation: float) -> tuple[np.ndarray, np.ndarray]:
    """RAW file -> ((raw - black) / (white - black) in camera RGB, saturation mask) at full
    size."""
    rgb, mask, _ = decode_raw_level(path, demosaic, saturation)
    return rgb, mask


def decode_raw_level(
    path: Path, demosaic: str, saturation: float, max_side: int = 0
) -> tuple[np.ndarray, np.ndarray, int]:
    """RAW file -> ((raw - black) / (white - black) in camera RGB, saturation mask, level), at
    the finest pyramid level whose long side is at most ``max_side`` (0: full size). Below
    full size LibRaw's half-size output (one pixel per 2×2 block: its red and blue samples
    sit a quarter of a level-1 pixel off the centre, the greens are averaged) is area-averaged
    on to the level."""
    level = 0

    def half(width: int, height: int) -> bool:
        nonlocal level
        level = frame_level(width, height, max_side)
        return level > 0

    mosaic, rgb = read_linear_rgb(path, demosaic, half)
    clipped = mosaic.clipped(saturation)
    if level > 0:
        # a half-size pixel is one 2×2 block, re-centred from its neighbours: unusable if any
        # sample of its block or the blocks around it clipped
        hh, hw = rgb.shape[:2]
        blocks = np.zeros((2 * hh, 2 * hw), bool)
        h, w = min(clipped.shape[0], 2 * hh), min(clipped.shape[1], 2 * hw)
        blocks[:h, :w] = clipped[:h, :w]
        near = maximum_filter(np.any(blocks.reshape(hh, 2, hw, 2), axis=(1, 3)), size=3)
        size = level_size(clipped.shape[1], clipped.shape[0], level)
        rgb = centre_half_size(rgb, mosaic.pattern, mosaic.colour_desc)
        return resize_area(rgb, size), resize_mask(near, size), level
    # the demosaic reads a neighbourhood: a pixel is unusable if any sample near it clipped
    radius = 1 if demosaic == "linear" else 2
    mask = maximum_filter(clipped, size=2 * radius + 1)
    if mask.shape != rgb.shape[:2]:
        size = (int(rgb.shape[1]), int(rgb.shape[0]))
        mask = cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
    return rgb, mask, 0


def centre_half_size(rgb: np.ndarray, pattern: np.ndarray | None, desc: str) -> np.ndarray:
    """LibRaw's half-size image with every channel at its pixel's centre: a channel's samples
    sit where the 2×2 colour-filter pattern puts them (red and blue a quarter pixel off,
    diagonally; the greens' mean at the centre), so each is shifted there bilinearly."""
    if pattern is None or pattern.shape != (2, 2):
        return rgb
    out = np.empty_like(rgb)
    channel = {"R": 0, "G": 1, "B": 2}
    for c in range(3):
        rows, cols = np.nonzero(np.isin(pattern, [i for i, n in enumerate(desc)
                                                  if channel.get(n) == c]))
        # sample at half-size coordinate (r + 0.5) / 2 of its block; the centre is 0.5
        dy, dx = rows.mean() / 2 - 0.25, cols.mean() / 2 - 0.25
        out[..., c] = cv2.warpAffine(
            np.ascontiguousarray(rgb[..., c]), np.array([[1.0, 0, -dx], [0, 1.0, -dy]]),
            rgb.shape[1::-1], flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_REPLICATE,
        )
    return out


def decode_linear(
    path: Path, record: FrameRecord, saturation: float
) -> tuple[np.ndarray, np.ndarray]:
    """Linear TIFF/NPY -> normalised RGB + mask. Integer data uses the manifest's
    ``black_level``/``white_level`` (default 0 and the dtype's maximum); float data is taken
    as already normalised, with white level ``white_level`` (default 1)."""
    data = np.load(path) if path.suffix == ".npy" else tifffile.imread(path)
    if data.ndim != 3 or data.shape[2] != 3:
        raise ValueError(f"expected an H x W x 3 array, got shape {data.shape}")
    if np.issubdtype(data.dtype, np.integer):
        black = float(record.extra.get("black_level", 0.0))
        white = float(record.extra.get("white_level", np.iinfo(data.dtype).max))
    else:
        black = float(record.extra.get("black_level", 0.0))
        white = float(record.extra.get("white_level", 1.0))
    values = data.astype(np.float32)
    mask = np.any(values - black >= saturation * (white - black), axis=2)
    return (values - black) / (white - black), mask


class FlatFieldDivider:
    """The session's flat field, its gain map made once per image size."""

    def __init__(self, flat: FlatField, where: str) -> None:
        self.flat = flat
        self.where = where
        self._maps: dict[tuple[int, int], np.ndarray] = {}

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        height, width = rgb.shape[:2]
        if (width, height) not in self._maps:
            self._maps[width, height] = self.flat.gain(width, height, self.where)
        return rgb / self._maps[width, height]


def session_flat_field(session: Session) -> tuple[FlatFieldDivider | None, list[Path]]:
    """The flat field session.yaml names (None without one) and its file in the snapshot."""
    choice = session.info.calibration.flat_field
    if choice is None:
        return None, []
    store = CalibrationStore(session.calibration_dir)
    entry, flat = store.flat_field(choice.entry, choice.version)
    where = f"flat field {entry.name!r} v{entry.version}"
    return FlatFieldDivider(flat, where), [store.root / entry.file]


def _decode_one(
    session: Session,
    record: FrameRecord,
    conf: DecodeConfig,
    flat: FlatFieldDivider | None = None,
    max_side: int = 0,
) -> tuple[np.ndarray, np.ndarray, int]:
    path = session.root / record.path
    if path.suffix.lower() in LINEAR_SUFFIXES:
        rgb, mask = decode_linear(path, record, conf.saturation)
        height, width = mask.shape
        level = frame_level(width, height, max_side)
        size = level_size(width, height, level)
        rgb, mask = resize_area(rgb, size), resize_mask(mask, size)
    else:
        rgb, mask, level = decode_raw_level(path, conf.demosaic, conf.saturation, max_side)
    if record.exposure_s <= 0 or record.iso <= 0:
        raise ValueError(f"exposure_s={record.exposure_s} and iso={record.iso} must be positive")
    rgb /= record.exposure_s * record.iso / 100.0
    if flat is not None:
        try:
            rgb = flat(rgb)  # the gain map is smooth: dividing after the reduction is the same
        except RigError as error:  # a frame of another size: that frame, not the session
            raise ValueError(error.problem) from error
    if not np.all(np.isfinite(rgb)):
        raise ValueError("decoded values are not finite")
    return rgb, mask, level


def _decode_in_order(
    session: Session,
    records: list[FrameRecord],
    conf: DecodeConfig,
    flat: FlatFieldDivider | None,
    max_side: int,
) -> Iterator[tuple[FrameRecord, tuple[np.ndarray, np.ndarray, int] | Exception]]:
    """Each record with its decoded frame, or the error that made it unusable, in order.
    Frames decode on one thread per core (LibRaw, OpenCV and NumPy release the GIL), at most
    two per thread ahead of the caller, so a long session never holds more than a few frames."""
    threads = min(DECODE_THREADS, usable_cores())

    def one(record: FrameRecord) -> tuple[np.ndarray, np.ndarray, int] | Exception:
        try:
            return _decode_one(session, record, conf, flat, max_side)
        except (rawpy.LibRawError, OSError, ValueError) as exc:
            return exc

    pool = ThreadPoolExecutor(threads, thread_name_prefix="decode")
    pending: deque[tuple[FrameRecord, Future[Any]]] = deque()
    try:
        for record in records:
            pending.append((record, pool.submit(one, record)))
            if len(pending) >= 2 * threads:
                head, future = pending.popleft()
                yield head, future.result()
        while pending:
            head, future = pending.popleft()
            yield head, future.result()
    finally:  # a stop or an error downstream: frames not started are not decoded
        pool.shutdown(wait=True, cancel_futures=True)


def tone_map(images: list[np.ndarray], max_side: int = 0) -> list[np.ndarray]:
    """Linear images -> 8-bit sRGB-like copies with one common exposure (for SIFT)."""
    scale = max(float(np.percentile(img, 99.5)) for img in images) or 1.0
    out = []
    for img in images:
        g = np.clip(img / scale, 0.0, 1.0) ** (1.0 / 2.2)
        u8 = (g * 255.0 + 0.5).astype(np.uint8)
        if max_side and max(u8.shape[:2]) > max_side:
            f = max_side / max(u8.shape[:2])
            u8 = np.asarray(cv2.resize(u8, None, fx=f, fy=f, interpolation=cv2.INTER_AREA))
        out.append(u8)
    return out


def sfm_image_name(view: int) -> str:
    return f"view_{view:04d}.png"


def list_unusable(bad: Mapping[str, str]) -> str:
    """``frame: why; …`` for one-line messages (the decode stage's, the reconstruct and batch
    commands')."""
    return "; ".join(f"{name}: {why}" for name, why in sorted(bad.items()))


def _bad(conf: DecodeConfig, bad: dict[str, str]) -> None:
    for name, why in bad.items():
        log.warning(
            "frame %s is unusable (%s)%s",
            name,
            why,
            ", skipped" if conf.on_bad_frame == "skip" else "",
        )
    if bad and conf.on_bad_frame == "stop":
        raise RigError(
            f"{len(bad)} frame(s) are unusable: {list_unusable(bad)}",
            "recapture them, restore them from a backup, or set decode.on_bad_frame: skip",
        )


def _decode(
    session: Session, conf: DecodeConfig, out_dir: Path, flat: FlatFieldDivider | None,
    max_side: int,
) -> None:
    if not session.frames:
        raise RigError(f"{session.root} has no frames in its manifest", "capture a session first")
    problems = verify_frames(session.root, session.frames)
    bad = {p.record.path: p.problem for p in problems}
    _bad(conf, bad)
    frames: list[DecodedFrame] = []
    best: dict[int, tuple[float, np.ndarray]] = {}  # view -> (score, image) for SfM
    records = [r for r in session.frames if r.path not in bad]
    decoded = _decode_in_order(session, records, conf, flat, max_side)
    for record, result in track(decoded, description="decoding frames", total=len(records)):
        if isinstance(result, Exception):
            bad[record.path] = f"cannot be decoded: {result}"
            _bad(conf, {record.path: bad[record.path]})
            continue
        rgb, mask, level = result
        stem = f"frame_{record.frame:05d}"
        # float16 halves the cache (3 significant digits, below sensor noise) unless the
        # exposure normalisation pushes values past its range (65504)
        small = float(rgb.max()) < FLOAT16_RANGE
        with atomic_output(out_dir / f"{stem}.npy") as tmp:
            np.save(tmp, rgb.astype(np.float16 if small else np.float32))
        with atomic_output(out_dir / f"{stem}_sat.npy") as tmp:
            np.save(tmp, mask)
        frames.append(
            DecodedFrame(
                record.frame,
                record.view,
                record.illumination,
                f"{stem}.npy",
                f"{stem}_sat.npy",
                record.path,
                record.exposure_s,
                record.iso,
                rgb.shape[0],
                rgb.shape[1],
                float(mask.mean()),
                dict(record.extra),
                level,
            )
        )
        score = _sfm_score(record.illumination, rgb, conf)
        if record.view not in best or score > best[record.view][0]:
            best[record.view] = (score, rgb)
    if not frames:
        raise RigError(f"no frame of {session.root} could be decoded", "see recon/log.txt")
    (out_dir / SFM_DIR).mkdir(exist_ok=True)
    views = sorted(best)
    for view, u8 in zip(
        views, tone_map([best[v][1] for v in views], conf.sfm_max_side), strict=True
    ):
        cv2.imwrite(str(out_dir / SFM_DIR / sfm_image_name(view)), u8[:, :, ::-1])
    DecodeIndex(frames, bad, {v: sfm_image_name(v) for v in views}).save(out_dir)
    log.info("decoded %d frames of %d views, %d skipped", len(frames), len(views), len(bad))


def _sfm_score(illumination: str, rgb: np.ndarray, conf: DecodeConfig) -> float:
    """Which frame of a view goes to SfM: the requested illumination, else the brightest."""
    if conf.sfm_illumination is not None and illumination == conf.sfm_illumination:
        return float("inf")
    return float(np.mean(rgb))


def run(
    conf: DecodeConfig | Mapping[str, Any], session: Session | Path, out_dir: Path,
    max_side: int = 0,
) -> Path:
    """Decode every frame of the session (opened by the caller, or its folder) into
    ``out_dir`` (resumable), each at the finest pyramid level whose long side is at most
    ``max_side`` (0: full size; :mod:`reconstruct.stages.resolution`)."""
    conf = from_mapping(DecodeConfig, conf, "config", "decode")
    session = Session.of(session)
    root = session.root
    # what `rig session verify` and `rig capture --resume` refuse, reconstruction refuses too
    check_session(root, session.frames, root / MANIFEST_FILE)
    flat, flat_files = session_flat_field(session)
    inputs = [root / MANIFEST_FILE, *flat_files] + [root / r.path for r in session.frames]
    settings = {**asdict(conf), "flat_field": None if flat is None else flat.where,
                "max_side": max_side}
    run_stage("decode", settings, inputs, out_dir,
              lambda: _decode(session, conf, out_dir, flat, max_side))
    return out_dir
