"""The oracle's inputs come from the reconstruction's own front-end stages."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from bench.paper_sim import _inputs
from core.errors import RigError
from reconstruct.run import front


@pytest.mark.parametrize(
    ("optimise", "glossy"),
    [({}, False), ({"gloss": "fit"}, True), ({"highlights": True}, True)],
)
def test_the_oracle_asks_for_the_front_end_the_reconstruction_ran(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, optimise: dict[str, Any], glossy: bool
) -> None:
    """Asked with another ``glossy``, the front end would build the initial mesh again (its
    stamp differs) and overwrite the one the reconstruction used and the report names."""
    seen: dict[str, Any] = {}

    def stop(*args: object, **kwargs: object) -> None:
        seen.update(kwargs)
        raise RigError("stopped after the front end's call", "")

    monkeypatch.setattr(front, "run_front", stop)
    monkeypatch.setattr("core.session.Session.open", lambda path: path)
    with pytest.raises(RigError, match="stopped after"):
        _inputs(tmp_path, None, {"optimise": optimise, "mesh": {"voxels": 64}})
    assert seen["glossy"] is glossy
