"""Gray-code structured light: per camera pixel, which projector column and row lit it.

Each bit is shown with its inverse, so a pixel's bit is the sign of ``on - off``: albedo,
ambient light and the projector's vignetting cancel, no global threshold is needed. A pixel is
trusted only where every decoded bit has a clear sign relative to the pixel's own full swing
(blurred stripe edges are rejected rather than guessed), where the swing itself stands out of
the image's bright level (shadows and background are rejected) and where no frame clipped.

Bits finer than the camera can resolve (a projector pixel smaller than a camera pixel) carry
no contrast anywhere; with ``auto_bits`` decoding stops at the first such bit and the code
addresses blocks of ``2**k`` projector pixels, which is what the camera actually resolves.

Frame labels (the manifest's ``illumination``) are :mod:`core.labels`'s; the Gray-code bit math
is :mod:`core.graycode`'s. The whole image stack is never held: frames are streamed bit by bit,
so full-size RAW sequences fit in memory.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from core.errors import RigError
from core.graycode import bit_count, gray_decode
from core.labels import AXES, parse_pattern_id, pattern_label

# label -> (linear image (H, W) or (H, W, C), saturation mask (H, W) or None)
Loader = Callable[[str], tuple[np.ndarray, np.ndarray | None]]


@dataclass(frozen=True)
class DecodeOptions:
    """``min_contrast``: a pixel's full swing (on - off of the coarse stripes) must exceed this
    fraction of the image's bright level, else it is shadowed or background;
    ``min_bit_contrast``: each decoded bit's |on - off| must exceed this fraction of the pixel's
    swing; ``auto_bits``: stop at the first bit whose median contrast over lit pixels is below
    ``resolve_contrast`` (unresolvable stripes); ``bright_percentile``: defines the bright level."""

    min_contrast: float = 0.05
    min_bit_contrast: float = 0.25
    auto_bits: bool = True
    resolve_contrast: float = 0.5
    bright_percentile: float = 99.5


@dataclass
class GrayDecoding:
    """Decoded projector coordinates of every camera pixel.

    ``col``/``row``: block indices (projector pixel // ``col_step`` / ``row_step``), -1 where
    invalid; ``valid``: the confidence mask; ``rejected``: pixel counts per reason.
    """

    col: np.ndarray
    row: np.ndarray
    valid: np.ndarray
    col_step: int
    row_step: int
    projector_size: tuple[int, int]
    rejected: dict[str, int] = field(default_factory=dict)

    def projector_xy(self) -> np.ndarray:
        """Projector pixel coordinates (H, W, 2) of each block's centre (COLMAP convention:
        the top-left pixel's centre is (0.5, 0.5)); NaN where invalid."""
        x = (self.col + 0.5) * self.col_step
        y = (self.row + 0.5) * self.row_step
        xy = np.stack([x, y], axis=-1).astype(float)
        xy[~self.valid] = np.nan
        return xy

    @property
    def blocks(self) -> tuple[int, int]:
        """Number of distinct (column, row) blocks."""
        w, h = self.projector_size
        return -(-w // self.col_step), -(-h // self.row_step)


def sequence_labels(labels: Iterable[str]) -> dict[str, dict[int, dict[bool, str]]]:
    """axis -> bit -> {inverse: label}, checked complete (every bit from 0 with its inverse)."""
    table: dict[str, dict[int, dict[bool, str]]] = {a: {} for a in AXES}
    for label in labels:
        pid = parse_pattern_id(label)
        if pid is not None:
            table[pid.axis].setdefault(pid.bit, {})[pid.inverse] = label
    for axis, bits in table.items():
        if not bits:
            raise RigError(
                f"no Gray-code frames for projector {axis}s",
                f"capture the {axis} patterns (gray-{axis}-00, gray-{axis}-00-inv, ...)",
            )
        missing = [
            pattern_label(axis, b, inv)
            for b in range(max(bits) + 1)
            for inv in (False, True)
            if inv not in bits.get(b, {})
        ]
        if missing:
            raise RigError(
                f"the Gray-code sequence lacks {', '.join(missing)}",
                "resume the capture (`rig capture --resume SESSION`) to take the missing frames",
            )
    return table


def _grey(image: np.ndarray) -> np.ndarray:
    data = np.asarray(image, dtype=np.float32)
    return data.sum(axis=-1) if data.ndim == 3 else data


def _difference(
    load: Loader, on_label: str, off_label: str, saturated: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None]:
    on, sat_on = load(on_label)
    off, sat_off = load(off_label)
    d = _grey(on) - _grey(off)
    for sat in (sat_on, sat_off):
        if sat is not None:
            saturated = sat.astype(bool) if saturated is None else saturated | sat
    return d, saturated


def decode_gray(
    labels: Iterable[str],
    load: Loader,
    projector_size: tuple[int, int] | None = None,
    options: DecodeOptions | None = None,
) -> GrayDecoding:
    """Decode one view's Gray-code frames into projector (column, row) blocks per pixel.

    ``labels``: the view's frame labels (others than Gray-code ids are ignored); ``load``
    returns a frame's linear image and saturation mask; ``projector_size`` (width, height)
    bounds the codes (default: the full range of the captured bits).
    """
    opt = options or DecodeOptions()
    table = sequence_labels(labels)
    n_bits = {a: max(table[a]) + 1 for a in AXES}
    size = projector_size or (2 ** n_bits["col"], 2 ** n_bits["row"])
    for axis, s in zip(AXES, size, strict=True):
        if bit_count(s) != n_bits[axis]:
            raise RigError(
                f"{n_bits[axis]} Gray-code {axis} bits captured for a projector "
                f"{s} pixels {'wide' if axis == 'col' else 'high'} (needs {bit_count(s)})",
                "give the projector size the sequence was generated for",
            )

    # pass 1: the two coarsest bits of each axis give every pixel's full swing (no pixel lies
    # on a stripe edge of both bit 0 and bit 1)
    saturated: np.ndarray | None = None
    diffs: dict[tuple[str, int], np.ndarray] = {}
    for axis in AXES:
        for bit in range(min(2, n_bits[axis])):
            pair = table[axis][bit]
            diffs[axis, bit], saturated = _difference(load, pair[False], pair[True], saturated)
    swing = np.max(np.abs(np.stack(list(diffs.values()))), axis=0)
    bright = float(np.percentile(swing, opt.bright_percentile))
    if bright <= 0:
        raise RigError(
            "the Gray-code frames show no stripes (pattern and inverse are identical)",
            "check that the projector lights the object and the exposure is not zero",
        )
    lit = swing > opt.min_contrast * bright
    sat = np.zeros(swing.shape, bool) if saturated is None else saturated
    lit_pixels = lit & ~sat

    # pass 2: stream every bit, MSB first, accumulating codes and the weakest bit's contrast
    codes: dict[str, np.ndarray] = {}
    used: dict[str, int] = {}
    weakest = np.full(swing.shape, np.inf, dtype=np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis in AXES:
            code = np.zeros(swing.shape, dtype=np.int64)
            used[axis] = 0
            for bit in range(n_bits[axis]):
                d = diffs.pop((axis, bit), None)
                if d is None:
                    pair = table[axis][bit]
                    d, saturated = _difference(load, pair[False], pair[True], saturated)
                rel = np.abs(d) / swing
                if (
                    opt.auto_bits
                    and bit >= 2
                    and lit_pixels.any()
                    and float(np.median(rel[lit_pixels])) < opt.resolve_contrast
                ):
                    break
                code = (code << 1) | (d > 0)
                weakest = np.minimum(weakest, rel)
                used[axis] += 1
            codes[axis] = gray_decode(code)
    sat = np.zeros(swing.shape, bool) if saturated is None else saturated
    steps = {a: 2 ** (n_bits[a] - used[a]) for a in AXES}
    blocks = {a: -(-s // steps[a]) for a, s in zip(AXES, size, strict=True)}
    in_range = (codes["col"] < blocks["col"]) & (codes["row"] < blocks["row"])
    sharp = weakest >= opt.min_bit_contrast
    valid = lit & ~sat & sharp & in_range
    rejected = {
        "shadowed": int((~lit).sum()),
        "saturated": int((lit & sat).sum()),
        "low_contrast": int((lit & ~sat & ~sharp).sum()),
        "out_of_range": int((lit & ~sat & sharp & ~in_range).sum()),
    }
    col = np.where(valid, codes["col"], -1)
    row = np.where(valid, codes["row"], -1)
    return GrayDecoding(col, row, valid, steps["col"], steps["row"], size, rejected)

