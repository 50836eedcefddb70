"""SIGINT and SIGTERM for `rig`, from a command's first instant to its exit: the first one
raises :class:`Interrupted` (a KeyboardInterrupt, so running code saves its state as for
Ctrl-C) and the command exits 128 + its number with one line; later ones are noted, never
raised, so the state being saved is not cut short. A stop that code swallowed (a library or an
extension module's init that clears every error) is raised again at the command's next log
line. Outside a command (start-up, exit) a signal ends the process at once with the same status
and line.

Imports only the standard library: it is installed before anything heavy is imported.
"""

from __future__ import annotations

import importlib.machinery
import logging
import os
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from types import FrameType, ModuleType
from typing import Any

SIGNALS = (signal.SIGINT, signal.SIGTERM)
# pycolmap's glog replaces the SIGTERM handler natively when this module loads, to print a
# stack dump; both signals wait while it loads and the handlers are put back before they land.
NATIVE_HANDLER_MODULES = frozenset({"pycolmap._core"})

Handler = Callable[[int, FrameType | None], Any] | int | None


class Interrupted(KeyboardInterrupt):
    """Signal ``signum`` arrived while a command ran."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class _State:
    first: int | None = None  # the first signal since install()
    raising = False  # a command runs: the first signal raises Interrupted
    raised = False  # the first signal was raised as Interrupted: it must reach the command
    stopped = False  # a command was stopped and says so: the rest is the interpreter's exit


_state = _State()


def exit_status(signum: int) -> int:
    """The shell's convention: 130 for SIGINT, 143 for SIGTERM."""
    return 128 + signum


def stop_line(signum: int, hint: str = "") -> str:
    name = signal.Signals(signum).name
    return f"rig: stopped by {name} (exit {exit_status(signum)})" + (f"; {hint}" if hint else "")


def received() -> int | None:
    """The first signal since the handlers were installed, if any."""
    return _state.first


def mark_stopped() -> None:
    """The command has taken its stop and is saying so: the stop is not raised again, and
    finalisers of objects the signal left half-built (a compiler's handle, a socket) that fail
    from now to the exit are logged, not printed after the stop line."""
    _state.stopped = True


def note(signum: int) -> None:
    """Record a signal another handler took (the capture loop's stop-after-this-frame)."""
    if _state.first is None:
        _state.first = signum


def _handle(signum: int, frame: FrameType | None) -> None:
    if _state.first is not None:
        return  # already stopping
    _state.first = signum
    if _state.raising:
        _state.raised = True
        raise Interrupted(signum)
    _exit_now(signum)


def _lost_stop() -> Interrupted | None:
    """The stop raised earlier, when the main thread runs on as if it never came: not stopped,
    and not inside an ``except`` or ``finally`` that is handling it (saving state)."""
    if not _state.raised or _state.stopped or _state.first is None or not _in_main_thread():
        return None
    return None if raised_by_a_stop(sys.exc_info()[1]) else Interrupted(_state.first)


def raised_by_a_stop(error: BaseException | None) -> bool:
    """Whether ``error`` is a Ctrl-C / SIGTERM stop or came while one unwound (a library that
    catches the interrupt and raises its own error, or a cleanup that failed on the way out)."""
    seen: set[int] = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return True
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return False


def _exit_now(signum: int) -> None:
    """Nothing is running that could save state: flush what was printed, say why, exit."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # a stream closed or in the middle of a write: the line still goes
            pass
    os.write(2, (stop_line(signum) + "\n").encode())
    os._exit(exit_status(signum))


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def handlers() -> dict[int, Handler]:
    """The handlers now installed, for :func:`restore`."""
    return {s: signal.getsignal(s) for s in SIGNALS} if _in_main_thread() else {}


def restore(previous: dict[int, Handler]) -> None:
    """The handlers as they were before :func:`install`; the command's signal is forgotten."""
    _state.raising = False
    _state.raised = False
    _state.first = None
    for sig, handler in previous.items():
        signal.signal(sig, signal.SIG_DFL if handler is None else handler)


def _set_handlers() -> None:
    for sig in SIGNALS:
        signal.signal(sig, _handle)


def _reraise_logged_stops() -> None:
    """Libraries that catch BaseException and log it (trimesh does, with a traceback) would
    swallow the stop: a log record carrying :class:`Interrupted` raises it again instead. So
    does any log record made while a swallowed stop is lost (:func:`_lost_stop`): every stage
    of a long command logs, so it stops there rather than running to its end."""
    make = logging.getLogRecordFactory()
    if getattr(make, "reraises_stops", False):
        return

    def factory(*args: Any, **kwargs: Any) -> logging.LogRecord:
        record = make(*args, **kwargs)
        if record.exc_info and isinstance(record.exc_info[1], Interrupted):
            raise record.exc_info[1]
        lost = _lost_stop()
        if lost is not None:
            raise lost
        return record

    factory.reraises_stops = True  # type: ignore[attr-defined]
    logging.setLogRecordFactory(factory)


def _redeliver_unraisable_stops() -> None:
    """A stop raised inside a finaliser or weakref callback (run by the garbage collector
    anywhere) cannot propagate and would print "Exception ignored": send the signal again,
    so it is raised once more outside the finaliser. Any other failing finaliser while a stop
    is under way goes to the log: the stop line stays the last thing on the terminal."""
    if getattr(sys.unraisablehook, "redelivers_stops", False):
        return
    previous = sys.unraisablehook
    log = logging.getLogger("rig")

    # defaults, not globals: the hook also runs at interpreter exit, after module globals go
    def hook(
        unraisable: Any,
        state: _State = _state,
        stop: type[Interrupted] = Interrupted,
        kill: Callable[[int, int], None] = os.kill,
    ) -> None:
        if isinstance(unraisable.exc_value, stop):
            state.first = None
            # from another thread, a moment later: a signal raised here would be handled
            # inside this hook, where it cannot propagate either
            again = threading.Timer(0.01, kill, (os.getpid(), unraisable.exc_value.signum))
            again.daemon = True
            again.start()
            return
        if state.first is not None or state.stopped:
            try:
                log.debug(
                    "while stopping, ignored %s in %r",
                    unraisable.exc_type.__name__,
                    unraisable.object,
                    exc_info=(unraisable.exc_type, unraisable.exc_value, unraisable.exc_traceback),
                )
            # logging shut down at exit, or a lost stop: nothing can leave this hook, and the
            # stop is raised again at the command's next log line
            except BaseException:
                pass
            return
        previous(unraisable)

    hook.redelivers_stops = True  # type: ignore[attr-defined]
    sys.unraisablehook = hook


def install(*, raising: bool = True) -> None:
    """Handle both signals from now on (main thread only: Python runs handlers there). With
    ``raising`` the first one raises :class:`Interrupted`; without, it exits at once. Signals a
    launcher blocked until now are delivered here."""
    if not _in_main_thread():
        return
    _state.first = None
    _state.raised = False
    _state.stopped = False
    _state.raising = raising
    _set_handlers()
    _reraise_logged_stops()
    _redeliver_unraisable_stops()
    _reinstall_after_native_imports()
    signal.pthread_sigmask(signal.SIG_UNBLOCK, SIGNALS)


class _ReinstallAfter:
    """A finder on ``sys.meta_path`` that loads a module that replaces the handlers natively
    with both signals blocked and puts the handlers back before unblocking them, so a signal
    sent while it loads is taken by rig's handler, never by the module's."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname not in NATIVE_HANDLER_MODULES:
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
        if spec is None or spec.loader is None:
            return spec
        exec_module = spec.loader.exec_module

        def exec_then_reinstall(module: ModuleType) -> None:
            main = _in_main_thread()
            mask = signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS) if main else None
            try:
                exec_module(module)
            finally:
                if main and signal.getsignal(signal.SIGTERM) is _handle:
                    _set_handlers()
                if mask is not None:
                    signal.pthread_sigmask(signal.SIG_SETMASK, mask)

        spec.loader.exec_module = exec_then_reinstall  # type: ignore[method-assign]
        return spec


_hook = _ReinstallAfter()


def _reinstall_after_native_imports() -> None:
    if _hook not in sys.meta_path:
        sys.meta_path.insert(0, _hook)
