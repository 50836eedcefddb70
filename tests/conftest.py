"""Shared pytest set-up: where the shared measured data lives, and opt-in hardware tests."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("MPLBACKEND", "Agg")
# `rig reconstruct` and friends compile the numba kernels in a child process on a cold cache
# (rig/warmup.py); the suite compiles in-process instead, and tests/rig/test_warmup.py tests
# the step.
os.environ.setdefault("SPECTRAL_RIG_WARMUP", "0")

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("SPECTRAL_RIG_SHARED", REPO.parent / "shared")) / "data"


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--device",
        action="append",
        default=[],
        metavar="KIND=ADDRESS",
        help="run hardware tests against a real device, e.g. --device serial=/dev/ttyUSB0",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    devices = config.getoption("--device")
    skip = pytest.mark.skip(reason="hardware test: name a device with --device KIND=ADDRESS")
    for item in items:
        if "hardware" in item.keywords and not devices:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def devices(request: pytest.FixtureRequest) -> dict[str, str]:
    """``--device KIND=ADDRESS`` options as a mapping."""
    out = {}
    for spec in request.config.getoption("--device"):
        kind, _, address = spec.partition("=")
        out[kind] = address
    return out


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` (measured data; never copied into the repository)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared data not found at {SHARED_DATA}")
    return SHARED_DATA
