"""The calibration store's index.yaml under concurrent changes: two processes adding entries at
once keep every entry (each change re-reads the index under the store's lock, core.lock)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from calibration import store as store_module
from calibration.store import CalibrationStore
from core.lock import InUse

ROOT = Path(__file__).parents[2]
ADDER = """
import sys, time
from pathlib import Path
import numpy as np
from calibration.store import CalibrationStore
root, prefix, go = sys.argv[1], sys.argv[2], Path(sys.argv[3])
w = np.arange(400.0, 701.0, 10.0)
print("ready", flush=True)
while not go.exists():
    time.sleep(0.001)
store = CalibrationStore(root)  # read before the other process's additions
for k in range(8):
    store.add_light(f"{prefix}{k}", w, np.full(w.size, 1.0 + k), {"source": "test"})
"""
HOLD = """
import sys
from core.lock import locked
with locked(sys.argv[1], "rig calibrate import"):
    print("held", flush=True)
    sys.stdin.read()
"""


def python(code: str, *args: str, stdin: bool = False) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-c", code, *args],
        stdin=subprocess.PIPE if stdin else None,
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env={"PYTHONPATH": str(ROOT)},
    )


def test_two_processes_adding_at_once_keep_every_entry(tmp_path: Path) -> None:
    root, go = tmp_path / "store", tmp_path / "go"
    procs = [python(ADDER, str(root), prefix, str(go)) for prefix in ("a", "b")]
    for proc in procs:
        assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
    go.touch()
    for proc in procs:
        assert proc.wait(timeout=300) == 0
        assert proc.stdout is not None
        proc.stdout.close()
    store = CalibrationStore(root)
    assert sorted(store.names("light")) == sorted(f"{p}{k}" for p in "ab" for k in range(8))
    assert all(store.light_spd(name).shape == (31,) for name in store.names("light"))
    assert not (root / ".lock").exists()


def test_two_rig_calibrate_imports_at_once_keep_both(tmp_path: Path) -> None:
    root = tmp_path / "store"
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "rig.cli", "calibrate", "import", f"colour:{illuminant}",
             "--kind", "light", "--name", illuminant, "--store", str(root)],
            cwd=ROOT,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        for illuminant in ("FL2", "FL11")
    ]
    for proc in procs:
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err.decode()
    assert sorted(CalibrationStore(root).names("light")) == ["FL11", "FL2"]


def test_a_change_waits_for_the_holder_then_names_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = tmp_path / "store"
    w = np.arange(400.0, 701.0, 10.0)
    CalibrationStore(root).add_light("LED1", w, np.ones_like(w), {"source": "test"})
    holder = python(HOLD, str(root), stdin=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        monkeypatch.setattr(store_module, "STORE_WAIT_S", 0.0)
        with pytest.raises(InUse, match=r"store is in use by `rig calibrate import` \(PID"):
            CalibrationStore(root).add_light("LED2", w, np.ones_like(w), {"source": "test"})
    finally:
        assert holder.stdin is not None
        holder.stdin.close()
        holder.wait()
    assert CalibrationStore(root).names("light") == ["LED1"]  # nothing written while refused
