"""SIGINT and SIGTERM for `rig`, from a command's first instant to its exit: the first one
raises :class:`Interrupted` (a KeyboardInterrupt, so running code saves its state as for
Ctrl-C) and the command exits 128 + its number with one line; later ones are noted, never
raised, so the state being saved is not cut short. A stop that code swallowed (a library that
clears every error) is raised again at the command's next log line; compiled modules load with
both signals held back. Outside a command (start-up, exit) a signal ends the process at once
with the same status and line. A stopped command's process ends without tearing the
interpreter down.

Imports only the standard library: it is installed before anything heavy is imported.
"""

from __future__ import annotations

import atexit
import importlib.machinery
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import CodeType, FrameType, ModuleType, TracebackType
from typing import Any, NoReturn

SIGNALS = (signal.SIGINT, signal.SIGTERM)

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
    if _inside_a_hook(frame):  # raised there it could not leave the hook: once it has left
        _send_again(signum)
        return
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


def was_stopped() -> bool:
    """Whether the last command was stopped and said so (:func:`mark_stopped`)."""
    return _state.stopped


def exit_stopped(status: int) -> NoReturn:
    """End the process of a stopped command: the exit functions run (logs flushed, temporary
    folders and worker processes cleaned up) but the interpreter is not torn down. A library
    the stop cut short while it loaded can crash freeing its half-built state in that teardown
    (an extension's objects freed with no thread state: SIGABRT after the stop line)."""
    atexit._run_exitfuncs()
    _flush_std_streams()
    os._exit(status)


def _exit_now(signum: int) -> None:
    """Nothing is running that could save state: flush what was printed, say why, exit."""
    _flush_std_streams()
    os.write(2, (stop_line(signum) + "\n").encode())
    os._exit(exit_status(signum))


def _flush_std_streams() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # a stream closed or in the middle of a write: what follows still goes
            pass


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


# the code of the hooks that take a stop Python cannot propagate (and send it again)
_HOOK_CODES: set[CodeType] = set()
# how often a resent stop looks whether the main thread has left the hook yet
RESEND_POLL_S = 0.005


def _inside_a_hook(frame: FrameType | None) -> bool:
    while frame is not None:
        if frame.f_code in _HOOK_CODES:
            return True
        frame = frame.f_back
    return False


def _main_thread_inside_a_hook() -> bool:
    return _inside_a_hook(sys._current_frames().get(threading.main_thread().ident or 0))


def _send_again(signum: int) -> None:
    """Send ``signum`` once more, so a stop a hook had to swallow is raised again outside it:
    from another thread, once the main thread has left the hook (a signal handled inside it
    could not leave it either)."""
    _state.first = None

    def deliver() -> None:
        while _main_thread_inside_a_hook():
            time.sleep(RESEND_POLL_S)
        os.kill(os.getpid(), signum)

    threading.Thread(target=deliver, name="stop again", daemon=True).start()


def _redeliver_printed_stops() -> None:
    """C code that reports an error by printing it and goes on (``PyErr_Print``: an extension
    importing a module lazily, which the stop cut short) would print the stop's traceback and
    drop the stop: send the signal again instead, as for a finaliser."""
    if getattr(sys.excepthook, "redelivers_stops", False):
        return
    previous = sys.excepthook

    def hook(
        kind: type[BaseException],
        error: BaseException,
        traceback: TracebackType | None,
        stop: type[Interrupted] = Interrupted,
        send_again: Callable[[int], None] = _send_again,
    ) -> None:
        if isinstance(error, stop):
            send_again(error.signum)
            return
        previous(kind, error, traceback)

    hook.redelivers_stops = True  # type: ignore[attr-defined]
    _HOOK_CODES.add(hook.__code__)
    sys.excepthook = hook


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
        send_again: Callable[[int], None] = _send_again,
    ) -> None:
        if isinstance(unraisable.exc_value, stop):
            send_again(unraisable.exc_value.signum)
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
    _HOOK_CODES.add(hook.__code__)
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
    _redeliver_printed_stops()
    _shield_extension_loads()
    signal.pthread_sigmask(signal.SIG_UNBLOCK, SIGNALS)


class _ShieldedExtensionLoader(importlib.machinery.ExtensionFileLoader):
    """Loads a compiled module with both signals blocked in the loading thread and rig's
    handlers put back before they are unblocked. Threads the module starts as it loads
    (OpenBLAS's pool) inherit the block, so the kernel never hands them a stop; a handler it
    installs natively (pycolmap's glog: a stack dump on SIGTERM) never sees one; and its init,
    which cannot take an exception raised into the Python it calls (numpy's ``import_array``
    prints it and fails), is never cut short. A signal sent meanwhile waits for the load."""

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        with _signals_held():
            return super().create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        with _signals_held():
            super().exec_module(module)


@contextmanager
def _signals_held() -> Iterator[None]:
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
    try:
        yield
    finally:
        if _in_main_thread() and signal.getsignal(signal.SIGTERM) is _handle:
            _set_handlers()
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _shield_extension_loads() -> None:
    """Compiled modules found on the path from now on load through
    :class:`_ShieldedExtensionLoader` (the finders already made are dropped)."""
    if any(getattr(hook, "shields_extensions", False) for hook in sys.path_hooks):
        return
    hook = importlib.machinery.FileFinder.path_hook(
        (_ShieldedExtensionLoader, importlib.machinery.EXTENSION_SUFFIXES),
        (importlib.machinery.SourceFileLoader, importlib.machinery.SOURCE_SUFFIXES),
        (importlib.machinery.SourcelessFileLoader, importlib.machinery.BYTECODE_SUFFIXES),
    )
    hook.shields_extensions = True  # type: ignore[attr-defined]
    sys.path_hooks.insert(0, hook)  # a path that is no folder (a zip) goes on to the next hook
    sys.path_importer_cache.clear()
