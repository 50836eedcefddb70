"""A printed ChArUco board: its geometry, profile snippet and printed layout.

The world frame of a board session is the board's: origin at the centre of the chessboard,
x to the right and y to the top of the printed sheet as read, z up out of the paper, metres.
OpenCV's board frame (origin at the top-left chessboard corner, y down the sheet, z into the
paper) is converted once here, so every other module sees world coordinates only.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import yaml

from core.config import bounded, from_mapping
from core.errors import RigError
from core.yamlio import read_yaml

# Sheet sizes (width, height) in metres, portrait.
PAPER_SIZES_M: dict[str, tuple[float, float]] = {
    "A4": (0.210, 0.297),
    "A3": (0.297, 0.420),
    "A2": (0.420, 0.594),
    "LETTER": (0.2159, 0.2794),
}
DEFAULT_DICTIONARY = "DICT_5X5_100"
DEFAULT_SQUARES = (10, 7)  # small squares: more corners survive around the object
DEFAULT_MARKER_RATIO = 0.75
PRINT_MARGIN_M = 0.012  # keeps the board clear of printers' unprintable rim and of the caption


@dataclass(frozen=True)
class BoardEntry:
    """A ``board:`` mapping as ``rig board`` prints it (squares and lengths required);
    :meth:`BoardSpec.from_dict` checks what spans keys."""

    squares: tuple[int, int] = bounded(min=1, max=1000)  # columns, rows
    square_length_m: float = bounded(above=0, max=10)
    marker_length_m: float = bounded(above=0, max=10)
    type: Literal["charuco"] = "charuco"
    dictionary: str = DEFAULT_DICTIONARY
    legacy_pattern: bool = False
    paper: str | None = None
    measured_square_length_m: float | None = bounded(None, above=0, max=10)


PRINT_SCALE_RANGE = (0.5, 2.0)  # a print scaled further is another board, or a typo

@dataclass(frozen=True)
class BoardSpec:
    """Geometry of a ChArUco board as designed, plus the square size measured on the print.

    ``squares`` is (columns, rows). ``measured_square_length_m``, when known, rescales the
    whole board (printers scale uniformly), so metric poses follow the paper, not the PDF.
    """

    squares: tuple[int, int] = DEFAULT_SQUARES
    square_length_m: float = 0.026
    marker_length_m: float = 0.0195
    dictionary: str = DEFAULT_DICTIONARY
    legacy_pattern: bool = False
    paper: str | None = None
    measured_square_length_m: float | None = None

    def __post_init__(self) -> None:
        sx, sy = self.squares
        if sx < 2 or sy < 2:
            raise RigError(
                f"board squares {sx}x{sy} are too few", "use at least 2x2 squares (e.g. 7x5)"
            )
        if not 0 < self.marker_length_m < self.square_length_m:
            raise RigError(
                f"board marker length {self.marker_length_m} m must be positive and smaller "
                f"than the square length {self.square_length_m} m",
                "use a marker about 0.75 of the square",
            )
        measured = self.measured_square_length_m
        if measured is not None and not (0 < measured < float("inf")):
            raise RigError(
                f"measured square length {self.measured_square_length_m} m is not positive",
                "enter the measured side of one chessboard square",
            )
        low, high = (f * self.square_length_m for f in PRINT_SCALE_RANGE)
        if measured is not None and not low <= measured <= high:
            raise RigError(
                f"measured square length {measured:g} m is not within [{low:g}, {high:g}] m "
                f"({PRINT_SCALE_RANGE[0]:g} to {PRINT_SCALE_RANGE[1]:g} times the designed "
                f"{self.square_length_m:g} m)",
                "measure the side of one chessboard square of this board's print",
            )
        if self.paper is not None and self.paper.upper() not in PAPER_SIZES_M:
            raise RigError(
                f"paper size {self.paper!r} is unknown", f"use one of {', '.join(PAPER_SIZES_M)}"
            )
        dictionary = _dictionary(self.dictionary)
        needed = (sx * sy) // 2
        if needed > dictionary.bytesList.shape[0]:
            raise RigError(
                f"a {sx}x{sy} board needs {needed} markers but {self.dictionary} has only "
                f"{dictionary.bytesList.shape[0]}",
                "pick a larger dictionary (e.g. DICT_5X5_250) or fewer squares",
            )

    # --- effective (as printed) geometry --------------------------------------------------

    @property
    def scale(self) -> float:
        """Printed / designed size."""
        if self.measured_square_length_m is None:
            return 1.0
        return self.measured_square_length_m / self.square_length_m

    @property
    def square_m(self) -> float:
        return self.square_length_m * self.scale

    @property
    def marker_m(self) -> float:
        return self.marker_length_m * self.scale

    @property
    def size_m(self) -> tuple[float, float]:
        """Width and height of the chessboard area as printed."""
        return self.squares[0] * self.square_m, self.squares[1] * self.square_m

    @property
    def n_corners(self) -> int:
        return (self.squares[0] - 1) * (self.squares[1] - 1)

    def paper_size_m(self) -> tuple[float, float] | None:
        """Sheet (width, height) as laid out under the board (landscape for a wide board)."""
        if self.paper is None:
            return None
        w, h = PAPER_SIZES_M[self.paper.upper()]
        if self.squares[0] > self.squares[1]:
            w, h = h, w
        return w * self.scale, h * self.scale

    def cv_board(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV board at the printed size."""
        return _cv_board(
            self.squares, self.square_m, self.marker_m, self.dictionary, self.legacy_pattern
        )

    def to_world(self, points_board: np.ndarray) -> np.ndarray:
        """OpenCV board-frame points (N, 3) -> world (z up, origin at the board centre)."""
        w, h = self.size_m
        p = np.asarray(points_board, dtype=float).reshape(-1, 3)
        return np.stack([p[:, 0] - w / 2, h / 2 - p[:, 1], -p[:, 2]], axis=1)

    def corner_points(self) -> np.ndarray:
        """World coordinates of every chessboard corner, indexed by ChArUco corner id (row by
        row from the top-left inner corner as printed, like OpenCV), in float64."""
        sx, sy = self.squares
        j, i = np.divmod(np.arange(self.n_corners), sx - 1)
        board = np.stack([(i + 1) * self.square_m, (j + 1) * self.square_m, 0 * i], axis=1)
        return self.to_world(board)

    def _marker_squares(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(marker ids, square rows, square columns) of the markers, from OpenCV's layout."""
        board = self.cv_board()
        centres = np.asarray(board.getObjPoints(), dtype=float).mean(axis=1)
        rows = (centres[:, 1] // self.square_m).astype(int)
        cols = (centres[:, 0] // self.square_m).astype(int)
        return np.asarray(board.getIds()).ravel(), rows, cols

    def marker_points(self) -> np.ndarray:
        """World coordinates of each marker's corners (n_markers, 4, 3), indexed by marker id,
        in OpenCV's order (top-left, top-right, bottom-right, bottom-left as printed)."""
        ids, rows, cols = self._marker_squares()
        inset = (self.square_m - self.marker_m) / 2
        x0, y0 = cols * self.square_m + inset, rows * self.square_m + inset
        m = self.marker_m
        xs = np.stack([x0, x0 + m, x0 + m, x0], axis=1)
        ys = np.stack([y0, y0, y0 + m, y0 + m], axis=1)
        board = np.stack([xs, ys, np.zeros_like(xs)], axis=2)
        out = np.empty_like(board)
        out[ids] = self.to_world(board.reshape(-1, 3)).reshape(-1, 4, 3)
        return out

    def black_rectangles(self) -> np.ndarray:
        """Every inked area as world rectangles (M, 4) of (x0, y0, x1, y1), non-overlapping:
        the black chessboard squares and each black module of each marker. One layout feeds
        the PDF/PNG print and the texture, so what is printed is what is simulated."""
        dictionary = self.cv_board().getDictionary()
        n = int(dictionary.markerSize) + 2  # (bits + 2)^2 cells with a one-module black border
        ids, rows, cols = self._marker_squares()
        sq = self.square_m
        sx, sy = self.squares
        # Black squares: squares without a marker (handles the legacy pattern too).
        has_marker = np.zeros((sy, sx), dtype=bool)
        has_marker[rows, cols] = True
        r, c = np.nonzero(~has_marker)
        rects = [np.stack([c * sq, r * sq, (c + 1) * sq, (r + 1) * sq], axis=1)]
        module = self.marker_m / n
        inset = (sq - self.marker_m) / 2
        for marker_id, row, col in zip(ids, rows, cols, strict=True):
            cells = cv2.aruco.generateImageMarker(dictionary, int(marker_id), n, borderBits=1)
            r, c = np.nonzero(cells < 128)
            x0, y0 = col * sq + inset, row * sq + inset
            rects.append(
                np.stack(
                    [
                        x0 + c * module,
                        y0 + r * module,
                        x0 + (c + 1) * module,
                        y0 + (r + 1) * module,
                    ],
                    axis=1,
                )
            )
        board_rects = np.concatenate(rects)
        w, h = self.size_m
        return np.stack(
            [
                board_rects[:, 0] - w / 2,
                h / 2 - board_rects[:, 3],
                board_rects[:, 2] - w / 2,
                h / 2 - board_rects[:, 1],
            ],
            axis=1,
        )

    # --- profile snippet --------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "charuco",
            "dictionary": self.dictionary,
            "squares": [int(self.squares[0]), int(self.squares[1])],
            "square_length_m": float(self.square_length_m),
            "marker_length_m": float(self.marker_length_m),
            "legacy_pattern": bool(self.legacy_pattern),
            "paper": self.paper,
            "measured_square_length_m": (
                None
                if self.measured_square_length_m is None
                else float(self.measured_square_length_m)
            ),
        }

    def to_yaml(self) -> str:
        """A profile snippet (``board:`` mapping) to paste into a rig profile."""
        header = (
            "# ChArUco board under the object (rig board). Lengths in metres as designed;\n"
            "# after printing, measure one square and set measured_square_length_m\n"
            "# (or run `rig board --snippet THIS_FILE --measured-square-mm MM`).\n"
        )
        return header + yaml.safe_dump({"board": self.to_dict()}, sort_keys=False)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "profile") -> BoardSpec:
        """From a profile's ``board:`` mapping (or a dict holding one)."""
        if isinstance(data, Mapping) and isinstance(data.get("board"), Mapping):
            data = data["board"]
        entry = from_mapping(BoardEntry, data, source, "board")
        try:
            return cls(
                entry.squares,
                entry.square_length_m,
                entry.marker_length_m,
                entry.dictionary,
                entry.legacy_pattern,
                entry.paper,
                entry.measured_square_length_m,
            )
        except RigError as exc:
            raise RigError(f"{source}: {exc.problem}", exc.fix) from exc

    @classmethod
    def from_yaml(cls, path: Path) -> BoardSpec:
        if not Path(path).exists():
            raise RigError(f"{path} does not exist", "generate it with `rig board --out`")
        data = read_yaml(Path(path), "board snippet", "fix or regenerate it with `rig board`")
        return cls.from_dict(data, source=str(path))

    def with_measured_square(self, measured_square_m: float) -> BoardSpec:
        return BoardSpec(
            self.squares,
            self.square_length_m,
            self.marker_length_m,
            self.dictionary,
            self.legacy_pattern,
            self.paper,
            measured_square_m,
        )

    @classmethod
    def fit_paper(
        cls,
        paper: str = "A4",
        squares: tuple[int, int] = DEFAULT_SQUARES,
        square_length_m: float | None = None,
        marker_ratio: float = DEFAULT_MARKER_RATIO,
        dictionary: str = DEFAULT_DICTIONARY,
    ) -> BoardSpec:
        """The board for a sheet: the largest whole-millimetre square that fits inside the
        print margins unless ``square_length_m`` is given (then it must fit)."""
        if paper.upper() not in PAPER_SIZES_M:
            raise RigError(
                f"paper size {paper!r} is unknown", f"use one of {', '.join(PAPER_SIZES_M)}"
            )
        if not 0.2 <= marker_ratio <= 0.95:
            raise RigError(f"marker ratio {marker_ratio} is out of range", "use 0.6-0.85")
        w, h = PAPER_SIZES_M[paper.upper()]
        if squares[0] > squares[1]:
            w, h = h, w
        largest = min((w - 2 * PRINT_MARGIN_M) / squares[0], (h - 2 * PRINT_MARGIN_M) / squares[1])
        if square_length_m is None:
            square_length_m = np.floor(largest * 1000 + 1e-9) / 1000
        elif square_length_m > largest + 1e-9:
            raise RigError(
                f"{squares[0]}x{squares[1]} squares of {square_length_m * 1000:g} mm do not fit "
                f"on {paper} with {PRINT_MARGIN_M * 1000:g} mm margins",
                f"use squares of at most {largest * 1000:.1f} mm, fewer squares or a larger sheet",
            )
        if square_length_m < 0.004:
            raise RigError(
                f"squares of {square_length_m * 1000:g} mm are too small to detect",
                "use fewer squares or a larger sheet",
            )
        return cls(
            squares=squares,
            square_length_m=float(square_length_m),
            marker_length_m=float(round(square_length_m * marker_ratio, 6)),
            dictionary=dictionary,
            paper=paper.upper(),
        )


def _dictionary(name: str) -> cv2.aruco.Dictionary:
    code = getattr(cv2.aruco, name, None) if name.startswith("DICT_") else None
    if not isinstance(code, int):
        names = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
        raise RigError(f"ArUco dictionary {name!r} is unknown", f"use one of {', '.join(names)}")
    return cv2.aruco.getPredefinedDictionary(code)


@functools.lru_cache(maxsize=16)
def _cv_board(
    squares: tuple[int, int], square: float, marker: float, dictionary: str, legacy: bool
) -> cv2.aruco.CharucoBoard:
    board = cv2.aruco.CharucoBoard(squares, square, marker, _dictionary(dictionary))
    board.setLegacyPattern(legacy)
    return board
