"""Auto-ranging a spectrometer's integration time, for every driver and the calibration
wizard: the time that puts the spectrum's peak near a target fraction of full scale."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

TARGET_FILL = 0.6  # peak as a fraction of full scale
TOLERANCE = 0.2  # relative distance of the peak from the target that is close enough
MAX_STEPS = 20
MAX_INTEGRATION_S = 600.0
SATURATED_BACK_OFF = 4.0  # a clipped peak says nothing of how far over it is
DARK_STEP_UP = 10.0  # no signal at all says nothing of how much longer is needed


def auto_range(
    read: Callable[[], tuple[float, float, bool]],
    set_time: Callable[[float], None],
    full_scale: float | None,
    *,
    target_fill: float = TARGET_FILL,
    tolerance: float = TOLERANCE,
    min_s: float = 0.0,
    max_s: float = MAX_INTEGRATION_S,
    max_steps: int = MAX_STEPS,
) -> bool:
    """Adjust the integration time by ``read()`` = (integration time s, peak counts,
    saturated) until the peak is within ``tolerance`` of ``target_fill`` × ``full_scale``:
    proportionally when the full scale is known, else doubling up to saturation and backing
    off once. Returns whether it settled."""
    for _ in range(max_steps):
        time_s, peak, saturated = read()
        if saturated:
            wanted = time_s / SATURATED_BACK_OFF
        elif full_scale is None:
            wanted = 2 * time_s
        elif peak <= 0:
            wanted = time_s * DARK_STEP_UP
        else:
            target = target_fill * full_scale
            if abs(peak / target - 1) < tolerance:
                return True
            wanted = time_s * float(np.clip(target / peak, 0.1, 100.0))
        wanted = float(np.clip(wanted, min_s, max_s))
        if wanted == time_s:  # pinned at a limit
            return False
        set_time(wanted)
        if full_scale is None and saturated:
            return True
    log.warning("spectrometer auto-range did not settle after %d steps", max_steps)
    return False


def auto_range_spectrometer(spectrometer: Any) -> None:
    """The driver's own ``auto_range`` when it has one, else :func:`auto_range` on its
    readings (full scale from ``full_scale`` or ``max_counts`` when it says); nothing when the
    integration time cannot be set."""
    own = getattr(spectrometer, "auto_range", None)
    if callable(own):
        own()
        return
    setter = getattr(spectrometer, "set_integration_time", None)
    if setter is None:
        return
    full = getattr(spectrometer, "full_scale", None) or getattr(spectrometer, "max_counts", None)

    def read() -> tuple[float, float, bool]:
        spectrum = spectrometer.measure()
        peak = float(np.max(np.asarray(spectrum.values, dtype=float)))
        return spectrum.integration_time_s, peak, spectrum.saturated

    auto_range(read, setter, full)
