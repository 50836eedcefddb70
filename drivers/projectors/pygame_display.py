"""A projector driven as a full-screen SDL2 window (pygame, optional extra ``projector``).

An LED projector plugged in as a second monitor is just a display: pick it by index.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core.errors import MissingDependencyError, RigError


def to_rgb8(image: np.ndarray) -> np.ndarray:
    """(H, W) or (H, W, 3), float in [0, 1] or uint8 -> (H, W, 3) uint8."""
    data = np.asarray(image)
    if data.ndim == 2:
        data = np.repeat(data[:, :, None], 3, axis=2)
    if data.ndim != 3 or data.shape[2] != 3:
        raise RigError(f"projector image has shape {data.shape}", "give (H, W) or (H, W, 3)")
    if data.dtype == np.uint8:
        return data
    if np.issubdtype(data.dtype, np.floating):
        if np.any(data < 0) or np.any(data > 1) or np.any(~np.isfinite(data)):
            raise RigError("projector image has values outside [0, 1]", "clip or rescale it")
        return np.round(data * 255).astype(np.uint8)
    raise RigError(f"projector image has dtype {data.dtype}", "use uint8 or float in [0, 1]")


class PygameProjector:
    driver_name = "pygame"

    def __init__(
        self,
        display: int = 0,
        size: tuple[int, int] | None = None,
        fullscreen: bool = True,
        pygame_module: Any = None,
    ) -> None:
        if pygame_module is None:
            try:
                import pygame as pygame_module
            except ImportError as error:
                raise MissingDependencyError(
                    "pygame", "projector", "needed to drive a projector"
                ) from error
        self._pg = pygame_module
        self._pg.display.init()
        sizes = self._pg.display.get_desktop_sizes()
        if not 0 <= display < len(sizes):
            self._pg.display.quit()
            raise RigError(
                f"display {display} does not exist ({len(sizes)} display(s) found)",
                f"plug in the projector and use a display index in 0..{len(sizes) - 1}",
            )
        self.display = display
        width, height = size or sizes[display]
        self.width, self.height = int(width), int(height)
        flags = self._pg.FULLSCREEN if fullscreen else 0
        self._screen = self._pg.display.set_mode((self.width, self.height), flags, display=display)
        self._pg.mouse.set_visible(False)
        self.blank()

    def show(self, image: np.ndarray) -> None:
        rgb = to_rgb8(image)
        if rgb.shape[:2] != (self.height, self.width):
            raise RigError(
                f"projector image is {rgb.shape[1]}x{rgb.shape[0]} but the display is "
                f"{self.width}x{self.height}",
                "generate patterns at the projector's resolution",
            )
        self._pg.surfarray.blit_array(self._screen, np.ascontiguousarray(rgb.transpose(1, 0, 2)))
        self._pg.display.flip()
        self._pg.event.pump()  # keep the window responsive so the OS does not mark it hung

    def shown(self) -> np.ndarray:
        """What the screen holds now, (H, W, 3) uint8 (for checks and tests)."""
        return np.asarray(self._pg.surfarray.array3d(self._screen)).transpose(1, 0, 2)

    def blank(self) -> None:
        self._screen.fill((0, 0, 0))
        self._pg.display.flip()
        self._pg.event.pump()

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "projector",
            "driver": self.driver_name,
            "display": self.display,
            "width": self.width,
            "height": self.height,
            "video_driver": self._pg.display.get_driver(),
        }

    def close(self) -> None:
        self._pg.display.quit()
