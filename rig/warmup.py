"""Compile the numba kernels in a throwaway process before the first reconstruction.

numba keeps every kernel it compiles alive in its process together with its LLVM modules, and
none of that is given back, so a run that compiles its kernels peaks higher than one that loads
them from numba's cache. So, once per install, a child process reconstructs a tiny simulated
capture — the same code path, so the kernels are compiled for the same types — and fills the
cache; the real run then only loads them. A stamp beside the cache records the kernel sources,
numba and CPU it was done for.

``python -m rig.warmup`` is the child; ``SPECTRAL_RIG_WARMUP=0`` turns the step off.
"""

from __future__ import annotations

import hashlib
import importlib.util
import io
import json
import logging
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import yaml
from rich.console import Console

from rig.progress_lines import ProgressLines

KERNEL_MODULES = (
    "reconstruct.optimise.kernels.cg",
    "reconstruct.optimise.kernels.normal_equations",
    "reconstruct.optimise.kernels.normals",
    "reconstruct.optimise.kernels.preconditioner",
    "reconstruct.optimise.kernels.rendering",
    "reconstruct.optimise.kernels.sampling",
    "reconstruct.initial_mesh.dense.plane_cost",
    "reconstruct.initial_mesh.dense.board_silhouette",
)
STAMP_FILE = "spectral-rig-warmup.json"
TIMEOUT_S = 1800
PROGRESS_EVERY_S = 30.0
CHILD = [sys.executable, "-m", "rig.warmup"]
# The tiny capture: bench.real_size's smoke size (every stage, every optimiser step runs)
_CAMERA = {"width": 320, "height": 240, "focal_px": 400.0}
_VIEWS = 8
_CONFIG = {"optimise": {"outer_iterations": 1, "light_iterations": 3, "joint_iterations": 3}}

log = logging.getLogger(__name__)


def warmup_key() -> str:
    """What the cached kernels depend on: their sources, numba's version and the host CPU."""
    import numba
    from llvmlite import binding

    digest = hashlib.sha256()
    for name in KERNEL_MODULES:
        spec = importlib.util.find_spec(name)
        if spec is None or spec.origin is None:
            raise ImportError(f"kernel module {name} not found")
        digest.update(Path(spec.origin).read_bytes())
    digest.update(numba.__version__.encode())
    digest.update(binding.get_host_cpu_name().encode())
    digest.update(binding.get_host_cpu_features().flatten().encode())
    return digest.hexdigest()


def stamp_path() -> Path | None:
    """Where the stamp goes: numba's cache folder for the optimiser's kernels (None: caching
    is off, so there is nothing to warm)."""
    from reconstruct.optimise.kernels.normal_equations import gram_products

    folder = getattr(getattr(gram_products, "_cache", None), "_cache_path", None)
    return None if folder is None else Path(folder) / STAMP_FILE


def is_warm(stamp: Path, key: str) -> bool:
    """Whether ``stamp`` records ``key`` (a missing or unreadable stamp: not warm)."""
    try:
        return bool(json.loads(stamp.read_text(encoding="utf-8"))["key"] == key)
    except (OSError, ValueError, KeyError, TypeError):
        return False


def compile_kernels_once(console: Console | None = None, command: list[str] | None = None) -> bool:
    """Run the child unless this install's kernels are already cached; True when they are
    (now or before). A failed child is only a warning: the run then compiles in its own
    process, as it would without this step."""
    if os.environ.get("SPECTRAL_RIG_WARMUP", "1") == "0":
        return False
    stamp = stamp_path()
    if stamp is None:
        return False
    key = warmup_key()
    if is_warm(stamp, key):
        return True
    message = (
        "compiling the numerical kernels once for this install (a tiny simulated "
        "reconstruction in a separate process, 1–3 min), so that this run only loads them"
    )
    if console is not None:  # a line that stays in logs, and a spinner or periodic lines
        console.print(message, highlight=False)
    else:
        log.info(message)
    try:
        with _waiting(console):
            proc = subprocess.run(
                command or CHILD,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
                timeout=TIMEOUT_S,
            )
    except (OSError, subprocess.TimeoutExpired) as exc:
        log.warning("kernel warm-up did not finish (%s); this run compiles them itself", exc)
        return False
    if proc.returncode != 0:
        tail = "\n".join(proc.stderr.strip().splitlines()[-5:])
        log.warning(
            "kernel warm-up exited %d; this run compiles them itself (and peaks higher):\n%s",
            proc.returncode,
            tail,
        )
        return False
    try:
        stamp.write_text(json.dumps({"key": key}), encoding="utf-8")
    except OSError as exc:  # the kernels are cached all the same; only the next check repeats
        log.warning("could not stamp the kernel cache %s: %s", stamp, exc)
    return True


@contextmanager
def _waiting(console: Console | None) -> Iterator[None]:
    """A spinner on a terminal; on a log or pipe, a plain line every ``PROGRESS_EVERY_S``
    (a log that stays silent for minutes looks hung)."""
    if console is None:
        yield
    elif console.is_terminal:
        with console.status("compiling kernels"):
            yield
    else:
        with ProgressLines(console, every_s=PROGRESS_EVERY_S) as lines:
            lines.description = "compiling kernels"  # the message above is the first line
            yield


def reconstruct_tiny_capture(folder: Path) -> None:
    """The child's work: a tiny sim capture reconstructed end to end in ``folder``."""
    from reconstruct.run.pipeline import run_reconstruction
    from rig.capture import run_capture
    from rig.demo_profile import demo_profile

    profile = demo_profile(_VIEWS)
    profile["name"] = "kernel-warmup"
    profile["poses"] = "known"
    profile["sim"] = {**profile.get("sim", {}), "camera": dict(_CAMERA)}
    path = folder / "profile.yaml"
    path.write_text(yaml.safe_dump(profile, sort_keys=False), encoding="utf-8")
    session = folder / "session"
    run_capture(path, session, yes=True, seed=0, console=Console(file=io.StringIO()))
    run_reconstruction(session, _CONFIG)


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="spectral-rig-warmup-") as tmp:
        reconstruct_tiny_capture(Path(tmp))
    return 0


if __name__ == "__main__":
    sys.exit(main())
