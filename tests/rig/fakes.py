"""Fake devices for capture tests: a camera writing small NumPy frames, a recording light.

Also runnable as a script (``python fakes.py SESSION [--resume]``) so tests can SIGKILL a
capture running in its own process without needing the simulated rig."""

from __future__ import annotations

import datetime as dt
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from drivers.protocols import CapturedFrame
from rig.capture.devices import RigDevices
from rig.profile import Profile, parse_profile

PROFILE: dict[str, Any] = {
    "name": "fake",
    "devices": {"light": {"driver": "sim"}, "camera": {"driver": "sim"}},  # opened by fake_rig
    "illuminations": {"A": {"r": 1.0}, "B": {"g": 1.0}, "C": {"b": 0.5, "w": 0.5}},
    "plan": {"views": 4, "illuminations": "all", "ambient": True},
    "light_mount": {"type": "plate", "offset_m": [0.1, 0.0, 0.0]},
}


def fake_profile(**plan: Any) -> Profile:
    data = {**PROFILE, "plan": {**PROFILE["plan"], **plan}}
    return parse_profile(data, "fake.yaml")


class FakeLight:
    channels: tuple[str, ...] = ("r", "g", "b", "w")
    illuminations: Mapping[str, Mapping[str, float]] = {}

    def __init__(self) -> None:
        self.log: list[dict[str, float] | None] = []

    def describe(self) -> dict[str, Any]:
        return {"model": "fake light", "serial": "L1"}

    def close(self) -> None:
        """Nothing to release."""

    def set_levels(self, levels: Mapping[str, float]) -> None:
        self.log.append(dict(levels))

    def set_illumination(self, name: str) -> None:
        self.set_levels(self.illuminations[name])

    def off(self) -> None:
        self.log.append(None)


class FakeCamera:
    """Writes a 16x16 uint16 frame whose level depends on the light; can fail on a shot."""

    def __init__(
        self,
        light: FakeLight,
        fail_at: int | None = None,
        level: int = 20000,
        delay_s: float = 0.0,
        corrupt: Callable[[int], bool] = lambda shot: False,
    ) -> None:
        self.light = light
        self.shots = 0
        self.fail_at = fail_at
        self.level = level
        self.delay_s = delay_s
        self.corrupt = corrupt

    def describe(self) -> dict[str, Any]:
        return {"model": "fake camera", "serial": "C1"}

    def close(self) -> None:
        """Nothing to release."""

    def capture(self, out_dir: Path, stem: str) -> CapturedFrame:
        self.shots += 1
        if self.fail_at is not None and self.shots == self.fail_at:
            raise OSError("USB device disconnected")
        time.sleep(self.delay_s)
        levels = self.light.log[-1] if self.light.log else None
        scale = sum(levels.values()) if levels else 0.05
        rng = np.random.default_rng(self.shots)
        frame = np.clip(rng.normal(self.level * scale, 50, (16, 16)), 0, 65535).astype(np.uint16)
        path = out_dir / f"{stem}.npy"
        np.save(path, frame)
        if self.corrupt(self.shots):  # a torn download: the header survives, the data not
            path.write_bytes(path.read_bytes()[:100])
        return CapturedFrame(
            (path,), 0.02, 100.0, "C1", dt.datetime.now(dt.timezone.utc).isoformat()
        )


def fake_rig(
    fail_at: int | None = None,
    level: int = 20000,
    delay_s: float = 0.0,
    corrupt: Callable[[int], bool] = lambda shot: False,
):
    """A device factory for run_capture(open_rig=...)."""
    made: dict[str, Any] = {}

    def open_rig(profile: Profile, seed: int, ask: Any) -> RigDevices:
        light = FakeLight()
        camera = FakeCamera(light, fail_at, level, delay_s, corrupt)
        made.update(light=light, camera=camera)
        return RigDevices(camera=camera, light=light, names={"camera": "fake", "light": "fake"})

    open_rig.made = made  # type: ignore[attr-defined]
    return open_rig


if __name__ == "__main__":
    from rig.capture import run_capture

    session = Path(sys.argv[1])
    resume = "--resume" in sys.argv
    run_capture(
        fake_profile(views=6), session, yes=True, resume=resume, open_rig=fake_rig(delay_s=0.01)
    )
