"""Fixtures of the front-stage tests (helpers in front_synthetic.py)."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path

import pytest
from front_synthetic import build_session


@pytest.fixture
def make_session(tmp_path: Path) -> Callable[..., Path]:
    """``make_session(views=..., illuminations=..., known_poses=..., size=...)`` -> session."""
    return partial(build_session, tmp_path)
