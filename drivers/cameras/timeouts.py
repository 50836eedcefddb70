"""A hard deadline around a blocking library call, so a hung camera never hangs a session.

The call runs on a daemon thread; past the deadline we stop waiting and raise. The stuck
thread cannot be killed, so the caller marks the device unusable (replug it).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, TypeVar

from core.errors import RigError

T = TypeVar("T")


def call_with_timeout(function: Callable[[], T], timeout_s: float, what: str) -> T:
    result: dict[str, Any] = {}

    def run() -> None:
        try:
            result["value"] = function()
        except BaseException as error:  # re-raised in the caller's thread
            result["error"] = error

    thread = threading.Thread(target=run, name=f"device: {what}", daemon=True)
    thread.start()
    thread.join(timeout_s)
    if thread.is_alive():
        raise RigError(
            f"{what} did not finish within {timeout_s:g} s (the device seems hung)",
            "switch the camera off and on or replug its cable, then resume the capture",
        )
    if "error" in result:
        raise result["error"]
    value: T = result["value"]
    return value
