"""The printable sheet: the board drawn as vector rectangles at its exact physical size.

PDF: vector, the page is the sheet (print at 100 %, no "fit to page"). PNG: the same drawing
rasterised at ``dpi`` with that DPI in the file's pHYs chunk, so image viewers and print
dialogs size it correctly.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.collections import PatchCollection
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from core.errors import RigError
from core.files import atomic_output
from reconstruct.poses.board.spec import PRINT_MARGIN_M, BoardSpec

INCH_M = 0.0254


def caption(spec: BoardSpec) -> str:
    sx, sy = spec.squares
    return (
        f"ChArUco {sx}x{sy} {spec.dictionary}  square {spec.square_m * 1000:g} mm  "
        f"marker {spec.marker_m * 1000:g} mm  board {spec.size_m[0] * 1000:g} x "
        f"{spec.size_m[1] * 1000:g} mm  -  print at 100 % (no fit-to-page), measure "
        f"{sx} squares and enter square = width / {sx} with --measured-square-mm"
    )


def draw_sheet(spec: BoardSpec) -> Figure:
    """A figure the size of the sheet with the board centred, in world metres."""
    paper = spec.paper_size_m()
    if paper is None:
        w, h = spec.size_m
        paper = (w + 2 * PRINT_MARGIN_M, h + 2 * PRINT_MARGIN_M)
    pw, ph = paper
    fig = Figure(figsize=(pw / INCH_M, ph / INCH_M))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(-pw / 2, pw / 2)
    ax.set_ylim(-ph / 2, ph / 2)
    ax.set_axis_off()
    rects = [Rectangle((x0, y0), x1 - x0, y1 - y0) for x0, y0, x1, y1 in spec.black_rectangles()]
    ax.add_collection(
        PatchCollection(rects, facecolor="black", edgecolor="none", linewidth=0, antialiased=False)
    )
    bottom = -spec.size_m[1] / 2
    ax.text(
        0.0,
        (bottom - ph / 2) / 2,
        caption(spec),
        ha="center",
        va="center",
        fontsize=5.5,
        color="0.35",
    )
    return fig


def write_sheet(spec: BoardSpec, path: Path, dpi: int = 300) -> Path:
    """Write the sheet to ``path`` (.pdf or .png)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".pdf", ".png"):
        raise RigError(f"cannot write a board to {path}", "name the output .pdf or .png")
    if suffix == ".png" and not 72 <= dpi <= 1200:
        raise RigError(f"--dpi {dpi} is out of range", "use 150-600 (300 is typical)")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = draw_sheet(spec)
    with atomic_output(path) as tmp:  # a full disk leaves no truncated sheet
        fig.savefig(tmp, dpi=dpi, facecolor="white", metadata=_metadata(spec, suffix))
    return path


def _metadata(spec: BoardSpec, suffix: str) -> dict[str, str]:
    key = "Title" if suffix == ".pdf" else "Description"
    return {key: caption(spec)}
