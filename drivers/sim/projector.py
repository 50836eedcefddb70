"""Simulated LED projector: a near point light at its optical centre whose colour per ray is
the shown image's pixel (linear, in [0, 1]) weighting its R, G, B primary SPDs."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from calibration.defaults import rgbcw_channel_spds
from core.errors import RigError
from reconstruct.model.camera import Intrinsics, Pose


class SimProjector:
    """Implements :class:`drivers.protocols.Projector`; the rig sets :attr:`pose` per view."""

    def __init__(
        self,
        intrinsics: Intrinsics,
        primary_spds: Mapping[str, np.ndarray] | None = None,
        serial: str = "SIM-PROJ-0001",
    ) -> None:
        self.intrinsics = intrinsics
        self.width = intrinsics.width
        self.height = intrinsics.height
        if primary_spds is None:
            bulb = rgbcw_channel_spds()
            primary_spds = {k: bulb[k] for k in ("r", "g", "b")}
        if set(primary_spds) != {"r", "g", "b"}:
            raise RigError(
                f"projector primaries {sorted(primary_spds)} given",
                "give exactly the SPDs of the r, g and b primaries",
            )
        self.primary_spds = {k: np.asarray(primary_spds[k], dtype=float) for k in "rgb"}
        self.serial = serial
        self.pose = Pose(np.eye(3), np.zeros(3))
        self.image: np.ndarray | None = None  # (H, W, 3) float, None = blank

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "projector",
            "model": "spectral-rig simulated LED projector",
            "serial": self.serial,
            "transport": "sim",
            "resolution": [self.width, self.height],
        }

    def close(self) -> None:
        self.blank()

    def show(self, image: np.ndarray) -> None:
        img = np.asarray(image)
        if img.shape[:2] != (self.height, self.width) or img.ndim not in (2, 3):
            raise RigError(
                f"pattern of shape {img.shape} for a {self.width}x{self.height} projector",
                f"pass an ({self.height}, {self.width}) or ({self.height}, {self.width}, 3) image",
            )
        f = img.astype(float) / 255.0 if img.dtype == np.uint8 else img.astype(float)
        if f.ndim == 2:
            f = np.repeat(f[..., None], 3, axis=2)
        f = np.clip(f[..., :3], 0.0, 1.0)
        self.image = f if f.any() else None

    def blank(self) -> None:
        self.image = None

    def spd(self) -> np.ndarray:
        """Mean emitted SPD over the frame (what a spectrometer facing the lens would see)."""
        if self.image is None:
            return np.zeros_like(self.primary_spds["r"])
        mean = self.image.reshape(-1, 3).mean(axis=0)
        stack = np.stack([self.primary_spds[k] for k in "rgb"])
        return mean @ stack
