from __future__ import annotations

from pathlib import Path

import pytest
from batch_sessions import capture


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One captured tiny session, copied by each test that needs a fresh one."""
    return capture(tmp_path_factory.mktemp("template") / "session")
