"""Checkpoints of the joint optimisation: the state after each completed stage.

The optimisation is the long part of ``rig reconstruct`` (minutes to hours); a kill, a crash or
Ctrl-C would otherwise lose all of it. After the light stage and after each joint stage the
state (vertices, basis weights, light, the starting weights, the history) is written
atomically to ``recon/optimise/checkpoint.npz`` under a key hashing the optimiser's source,
the settings and every input array, so a later run with the same inputs resumes after the last
completed stage and ends with the same numbers as a run never interrupted; any other code,
setting or input starts afresh.
"""

from __future__ import annotations

import hashlib
import json
import logging
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.files import atomic_output
from reconstruct.optimise.settings import OptimiseInput, OptimiseSettings

log = logging.getLogger(__name__)

FILE = "checkpoint.npz"


@dataclass
class OptimiseState:
    """Everything the optimisation needs to go on after ``stage`` (0: the light stage,
    k ≥ 1: joint stage k); ``done``: no stage is left."""

    stage: int
    done: bool
    vertices: np.ndarray
    alpha: np.ndarray
    light: np.ndarray
    initial_alpha: np.ndarray
    observed: np.ndarray
    n_observations: int
    history: list[dict[str, Any]]
    seconds: dict[str, float]


def code_digest() -> bytes:
    """Hash of the optimiser's source: a checkpoint written by other code is not resumed."""
    digest = hashlib.sha256()
    for path in sorted(Path(__file__).parent.glob("*.py")):
        digest.update(path.read_bytes())
    return digest.digest()


def input_key(inp: OptimiseInput, settings: OptimiseSettings) -> str:
    """Hash of the optimiser's code, the settings and every array the optimisation reads."""
    digest = hashlib.sha256(code_digest())
    digest.update(json.dumps(asdict(settings), sort_keys=True, default=str).encode())
    rig, frames = inp.rig, inp.frames
    arrays: list[Any] = [inp.vertices, inp.faces, inp.visibility, inp.basis.B, rig.responses]
    arrays += [frames.view, frames.illumination, frames.images, frames.valid, frames.weight]
    arrays += [inp.initial_light, inp.initial_alpha, inp.observed]
    arrays += [np.asarray(p.R) for p in rig.poses] + [np.asarray(p.t) for p in rig.poses]
    arrays += [np.asarray(i.params, dtype=float) for i in rig.intrinsics]
    for array in arrays:
        if array is None:
            digest.update(b"none")
            continue
        a = np.ascontiguousarray(array)
        digest.update(f"{a.dtype}{a.shape}".encode())
        digest.update(a.data)
    return digest.hexdigest()


class Checkpoint:
    """Saves and loads :class:`OptimiseState` at ``path`` for inputs hashing to ``key``."""

    def __init__(self, path: Path, key: str) -> None:
        self.path = Path(path)
        self.key = key

    def save(self, state: OptimiseState) -> None:
        """Write atomically (temporary name, fsync, rename): a kill leaves the old or the new."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        meta = {
            "key": self.key,
            "stage": state.stage,
            "done": state.done,
            "n_observations": state.n_observations,
            "history": state.history,
            "seconds": state.seconds,
        }
        with atomic_output(self.path) as tmp, open(tmp, "wb") as handle:
            np.savez(
                handle,
                meta=np.array(json.dumps(meta, default=_plain)),
                vertices=state.vertices,
                alpha=state.alpha,
                light=state.light,
                initial_alpha=state.initial_alpha,
                observed=state.observed,
            )

    def load(self) -> OptimiseState | None:
        """The saved state, or None without a checkpoint for these inputs (a stale or unreadable
        one is left to be overwritten)."""
        if not self.path.is_file():
            return None
        try:
            with np.load(self.path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                arrays = {k: np.array(data[k]) for k in data.files if k != "meta"}
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as error:
            log.warning("ignoring the unreadable checkpoint %s (%s)", self.path, error)
            return None
        if meta.get("key") != self.key:
            log.info("checkpoint %s is for other inputs or settings: starting afresh", self.path)
            return None
        return OptimiseState(
            stage=int(meta["stage"]),
            done=bool(meta["done"]),
            vertices=arrays["vertices"],
            alpha=arrays["alpha"],
            light=arrays["light"],
            initial_alpha=arrays["initial_alpha"],
            observed=arrays["observed"],
            n_observations=int(meta["n_observations"]),
            history=list(meta["history"]),
            seconds={str(k): float(v) for k, v in meta["seconds"].items()},
        )


def _plain(value: Any) -> Any:
    """JSON for the NumPy scalars and arrays in the history."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")
