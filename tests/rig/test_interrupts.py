"""SIGINT and SIGTERM in `rig`: 130 / 143 and one line whatever the command was doing, a second
signal while state is saved neither lost nor raised, pycolmap's native SIGTERM handler
replaced, and signals before or after the command exiting at once."""

from __future__ import annotations

import argparse
import ctypes
import logging
import os
import shutil
import signal
import subprocess
import sys
import sysconfig
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from core import interrupts
from rig import cli
from rig.commands import session as session_command

REPO = Path(__file__).resolve().parents[2]
STOP_LINE = "rig: stopped by"
KILL_SELF_WITH_SIGTERM = b"import os, signal; os.kill(os.getpid(), signal.SIGTERM)"


def run_with(
    monkeypatch: pytest.MonkeyPatch, command: Callable[[argparse.Namespace], int]
) -> int:
    """`rig session info X` with its handler replaced by ``command``."""
    monkeypatch.setattr(session_command, "handle_info", command)
    return cli.main(["session", "info", "x"])


def kill_self(signum: int) -> None:
    os.kill(os.getpid(), signum)


def one_stop_line(err: str, name: str, code: int) -> None:
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines and lines[-1].startswith(f"{STOP_LINE} {name} (exit {code})"), err
    assert sum(STOP_LINE in line for line in lines) == 1, err
    assert "Traceback" not in err and "internal error" not in err


def stopped_by_sigterm(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    command: Callable[[argparse.Namespace], int],
) -> str:
    """Run ``command`` as :func:`run_with` does; it must end 143 with the one stop line.
    Returns what it printed on stderr."""
    assert run_with(monkeypatch, command) == 143
    err = capsys.readouterr().err
    one_stop_line(err, "SIGTERM", 143)
    return err


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_during_a_command_exits_128_plus_its_number(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], signum: int, code: int
) -> None:
    saved: list[str] = []

    def command(args: argparse.Namespace) -> int:
        try:
            kill_self(signum)
            raise AssertionError("the signal did not stop the command")
        finally:
            saved.append("state")  # unwinding code runs, as for Ctrl-C

    before = {s: signal.getsignal(s) for s in interrupts.SIGNALS}
    assert run_with(monkeypatch, command) == code
    one_stop_line(capsys.readouterr().err, signal.Signals(signum).name, code)
    assert saved == ["state"]
    assert {s: signal.getsignal(s) for s in interrupts.SIGNALS} == before


def test_a_second_signal_while_saving_state_is_noted_not_raised(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    saved: list[str] = []

    def command(args: argparse.Namespace) -> int:
        try:
            kill_self(signal.SIGTERM)
        finally:
            kill_self(signal.SIGINT)  # the user presses Ctrl-C as the state is written
            saved.append("state")
        return 0

    stopped_by_sigterm(monkeypatch, capsys, command)
    assert saved == ["state"]


def test_a_stop_a_library_catches_and_logs_is_raised_again(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    library = logging.getLogger("trimesh")  # catches BaseException and logs it with exc_info
    went_on: list[str] = []

    def command(args: argparse.Namespace) -> int:
        try:
            kill_self(signal.SIGTERM)
        except BaseException:
            library.warning("unable to use sparse matrix, falling back!", exc_info=True)
        went_on.append("the library's fallback")
        return 0

    stopped_by_sigterm(monkeypatch, capsys, command)
    assert went_on == []


STAGE_LOG = logging.getLogger("tests.interrupts.stage")  # a command's progress lines
STAGE_LOG.setLevel(logging.INFO)


def test_a_stop_a_library_swallows_is_raised_at_the_next_log_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """An extension module's init (or any C code) that clears every error loses the stop; the
    command must not run on to its end."""
    went_on: list[str] = []

    def command(args: argparse.Namespace) -> int:
        try:
            kill_self(signal.SIGTERM)
        except BaseException:
            pass  # cleared, with nothing said
        went_on.append("the library's caller")
        STAGE_LOG.info("next stage: running")
        went_on.append("the next stage")
        return 0

    stopped_by_sigterm(monkeypatch, capsys, command)
    assert went_on == ["the library's caller"]


@pytest.mark.parametrize("converted", [False, True])
def test_log_lines_while_the_stop_is_handled_do_not_raise_it_again(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], converted: bool
) -> None:
    """Saving state logs (the status, the timings), in a ``finally`` or in an ``except`` that
    turns the stop into the caller's own error."""
    saved: list[str] = []

    def command(args: argparse.Namespace) -> int:
        try:
            try:
                kill_self(signal.SIGTERM)
            except KeyboardInterrupt as stop:
                if converted:
                    raise RuntimeError("stopped while saving") from stop
                raise
        finally:
            STAGE_LOG.info("status: interrupted")
            saved.append("state")
        return 0

    stopped_by_sigterm(monkeypatch, capsys, command)
    assert saved == ["state"]


def test_a_signal_the_command_took_itself_is_not_raised_at_its_log_lines(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The capture loop's first signal finishes the frame in flight, which logs."""
    finished: list[str] = []

    def command(args: argparse.Namespace) -> int:
        interrupts.note(signal.SIGTERM)
        STAGE_LOG.info("frame 12: saved")
        finished.append("the frame in flight")
        return 0

    stopped_by_sigterm(monkeypatch, capsys, command)
    assert finished == ["the frame in flight"]


def test_a_stop_raised_in_a_finaliser_is_delivered_again(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    went_on: list[str] = []

    class Finalised:
        def __del__(self) -> None:  # Python can only report an exception raised here
            kill_self(signal.SIGTERM)

    def command(args: argparse.Namespace) -> int:
        Finalised()  # collected at once: the stop arrives inside __del__
        for _ in range(200):  # the command goes on; the stop comes back within a moment
            time.sleep(0.01)
        went_on.append("after the finaliser")
        return 0

    err = stopped_by_sigterm(monkeypatch, capsys, command)
    assert "Exception ignored" not in err and went_on == []


def test_a_stop_that_c_code_printed_and_cleared_is_delivered_again(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """An extension reporting an error with ``PyErr_Print`` and going on (a lazy import the
    stop cut short) neither prints the stop's traceback nor drops the stop."""
    went_on: list[str] = []

    def command(args: argparse.Namespace) -> int:
        # C code that runs Python, prints what it raised (PyErr_Print) and returns -1
        assert ctypes.pythonapi.PyRun_SimpleString(KILL_SELF_WITH_SIGTERM) == -1
        for _ in range(200):  # the command goes on; the stop comes back within a moment
            time.sleep(0.01)
        went_on.append("after the printed stop")
        return 0

    stopped_by_sigterm(monkeypatch, capsys, command)
    assert went_on == []


def test_a_failure_the_signal_caused_is_reported_as_the_signal(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def command(args: argparse.Namespace) -> int:
        try:
            kill_self(signal.SIGTERM)
        except KeyboardInterrupt as exc:  # e.g. a library turning it into its own error
            raise RuntimeError("Cannot import the C++ backend") from exc
        return 0

    stopped_by_sigterm(monkeypatch, capsys, command)


def test_a_signal_the_command_took_itself_still_sets_the_exit_status(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The capture loop takes SIGTERM to finish the frame in flight, then returns normally."""

    def command(args: argparse.Namespace) -> int:
        interrupts.note(signal.SIGTERM)
        return 0

    stopped_by_sigterm(monkeypatch, capsys, command)


def test_the_stop_line_says_how_to_resume_a_capture(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from rig.commands import capture

    args = argparse.Namespace(out=tmp_path / "s", resume=None, profile="sim")
    assert "--resume" in capture.stop_hint(args) and "--profile sim" in capture.stop_hint(args)
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "session.yaml").write_text("{}")
    assert capture.stop_hint(args) == (
        f"every completed frame is saved; resume with `rig capture --resume {tmp_path / 's'}`"
    )


def python(code: str, *, block: bool = False) -> subprocess.CompletedProcess[str]:
    """``python -c code`` from the repository, optionally started with both signals blocked."""
    def blocked() -> None:
        signal.pthread_sigmask(signal.SIG_BLOCK, interrupts.SIGNALS)

    return subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=blocked if block else None,
        check=False,
    )


def test_pycolmap_native_sigterm_handler_is_replaced() -> None:
    """Its glog would print a native stack dump and kill the process."""
    proc = python(
        "import os, signal, time\n"
        "from core import interrupts\n"
        "interrupts.install()\n"
        "import pycolmap\n"
        "try:\n"
        "    os.kill(os.getpid(), signal.SIGTERM); time.sleep(10)\n"
        "except interrupts.Interrupted as stop:\n"
        "    raise SystemExit(interrupts.exit_status(stop.signum))\n"
    )
    assert proc.returncode == 143, proc.stderr
    assert "*** Aborted" not in proc.stderr and "received by PID" not in proc.stderr


NATIVE_LIKE_C = r"""
#include <Python.h>
#include <pthread.h>
#include <signal.h>
#include <unistd.h>

static void *idle(void *unused) { for (;;) pause(); return NULL; }

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "native_like", NULL, -1, NULL};

PyMODINIT_FUNC PyInit_native_like(void) {
    pthread_t pool; /* a thread pool started as the library loads, as OpenBLAS's */
    pthread_create(&pool, NULL, idle, NULL);
    pthread_detach(pool);
    signal(SIGTERM, SIG_DFL); /* a handler installed natively, as glog's (this one kills) */
    kill(getpid(), SIGTERM);
    usleep(50000); /* time for the kernel to hand the signal to any thread that takes it */
    return PyModule_Create(&module);
}
"""


def compiled_module(folder: Path, name: str, source: str) -> None:
    """``name`` built from C ``source`` into ``folder`` (skips without a C compiler)."""
    compiler = shutil.which("cc")
    if compiler is None:
        pytest.skip("no C compiler to build the test's extension module")
    (folder / f"{name}.c").write_text(source)
    target = folder / f"{name}{sysconfig.get_config_var('EXT_SUFFIX')}"
    include = f"-I{sysconfig.get_paths()['include']}"
    command = [compiler, "-shared", "-fPIC", "-pthread", include, f"{name}.c", "-o", target.name]
    subprocess.run(command, cwd=folder, check=True, capture_output=True)


def test_a_sigterm_while_a_compiled_module_loads_reaches_rig(tmp_path: Path) -> None:
    """A compiled module that, as it loads, starts a thread, installs its own SIGTERM handler
    natively (as pycolmap's glog does) and is sent SIGTERM in that very instant: rig's handler
    takes it once the module has loaded, not the module's nor its thread."""
    compiled_module(tmp_path, "native_like", NATIVE_LIKE_C)
    proc = python(
        "import sys, time\n"
        f"sys.path.insert(0, {str(tmp_path)!r})\n"
        "from core import interrupts\n"
        "interrupts.install()\n"
        "try:\n"
        "    import native_like\n"
        "    time.sleep(10)\n"
        "except interrupts.Interrupted as stop:\n"
        "    print('loaded' if 'native_like' in sys.modules else 'cut short')\n"
        "    raise SystemExit(interrupts.exit_status(stop.signum))\n"
    )
    assert proc.returncode == 143, (proc.returncode, proc.stderr)
    assert proc.stdout == "loaded\n"


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_outside_a_command_a_signal_exits_at_once_with_the_line(signum: int) -> None:
    proc = python(
        "import os, sys, time\n"
        "from core import interrupts\n"
        "interrupts.install(raising=False)\n"
        "print('printed before', flush=False)\n"
        f"os.kill(os.getpid(), {int(signum)}); time.sleep(10)\n"
    )
    code = interrupts.exit_status(signum)
    assert proc.returncode == code and proc.stdout == "printed before\n"
    assert proc.stderr == f"{STOP_LINE} {signal.Signals(signum).name} (exit {code})\n"


def test_a_signal_sent_before_the_handlers_existed_is_taken_when_they_do() -> None:
    """A launcher that blocked the signals: they wait, then stop the command at its start."""
    proc = python(
        "import os, signal\n"
        "os.kill(os.getpid(), signal.SIGTERM)\n"
        "from rig.cli import run\n"
        "run()\n",
        block=True,
    )
    assert proc.returncode == 143, proc.stderr
    assert proc.stderr == f"{STOP_LINE} SIGTERM (exit 143)\n"


def test_a_stopped_command_ends_without_tearing_the_interpreter_down() -> None:
    """A library the stop cut short while it loaded can crash freeing its half-built state as
    the interpreter is torn down (once in CI: SIGABRT after the stop line). The exit
    functions still run."""
    proc = python(
        "import atexit, os, signal, sys\n"
        "from rig import cli\n"
        "from rig.commands import session\n"
        "class HalfBuilt:\n"
        "    def __del__(self):  # an extension freeing what its interrupted init left\n"
        "        os.abort()\n"
        "def command(args):\n"
        "    global kept\n"
        "    kept = HalfBuilt()  # freed only as the interpreter is torn down\n"
        "    atexit.register(print, 'exit functions ran')\n"
        "    os.kill(os.getpid(), signal.SIGINT)\n"
        "session.handle_info = command\n"
        "sys.argv = ['rig', 'session', 'info', 'x']\n"
        "cli.run()\n",
    )
    assert proc.returncode == 130, proc.stderr
    one_stop_line(proc.stderr, "SIGINT", 130)
    assert proc.stdout == "exit functions ran\n"


def test_a_finaliser_the_stop_left_half_built_stays_off_the_terminal() -> None:
    """llvmlite's handles, cut short mid-construction by the signal, fail in ``__del__`` as
    the interpreter exits: the stop line stays the last line, the failure goes to the log."""
    proc = python(
        "import argparse, logging, os, signal, sys\n"
        "from rig import cli\n"
        "from rig.commands import session\n"
        "class HalfBuilt:\n"
        "    def __del__(self):\n"
        "        raise AttributeError('no attribute _as_parameter_')\n"
        "def command(args):\n"
        "    global kept\n"
        "    kept = HalfBuilt()  # collected only when the interpreter exits\n"
        "    os.kill(os.getpid(), signal.SIGINT)\n"
        "session.handle_info = command\n"
        "sys.exit(cli.main(['session', 'info', 'x']))\n"
    )
    assert proc.returncode == 130, proc.stderr
    one_stop_line(proc.stderr, "SIGINT", 130)
    assert "Exception ignored" not in proc.stderr, proc.stderr
