"""Resuming opens the devices of the session's own profile snapshot, and a session folder may
come from someone else: a ``subprocess`` transport in it would run a program named by that
folder (a ``record:`` would write where it says). Such devices are opened only after the
person confirms (or with an explicit flag)."""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path

from core.errors import RigError
from core.session import SESSION_FILE
from drivers.registry import resolved_transport
from rig.capture.devices import Ask
from rig.profile import Profile

TRUST_FLAG = "--trust-session-devices"


def session_programs(profile: Profile) -> list[str]:
    """What opening the snapshot's devices would do beyond talking to a device: run a
    program (``subprocess`` transport) or write a file (``record:``)."""
    found = []
    for kind in ("camera", "light", "projector", "spectrometer"):
        spec = profile.device(kind) or {}
        given = spec.get("transport")
        if given is not None and not isinstance(given, Mapping):
            continue  # opening it fails with its own message before anything runs
        transport = resolved_transport(str(spec.get("driver")), given)
        if transport.get("type") == "subprocess":
            command = transport.get("command")
            shown = " ".join(map(str, command)) if isinstance(command, list) else str(command)
            found.append(f"devices.{kind} runs `{shown}`")
        if transport.get("record"):  # a log written wherever the snapshot says
            found.append(f"devices.{kind} writes {transport['record']}")
    return found


def confirm_session_devices(
    session_dir: Path, profile: Profile, *, trusted: bool, ask: Ask | None, interactive: bool
) -> None:
    """Return when nothing in the snapshot runs a program, the person said ``trusted``
    (the flag) or confirms at the prompt; else raise RigError naming the program."""
    programs = session_programs(profile)
    if not programs or trusted:
        return
    where = f"{session_dir / SESSION_FILE}: {'; '.join(programs)}"
    fix = f"check that command, then resume with {TRUST_FLAG}"
    if ask is None or not interactive:
        raise RigError(f"{where} (a program from the session's device snapshot)", fix)
    answer = ask(f"{where}. Resuming does this. Go ahead? [y/N] ")
    if answer.strip().lower() not in ("y", "yes"):
        raise RigError(f"{where}: not confirmed, nothing was run", fix)


def stdin_is_tty() -> bool:
    return sys.stdin is not None and sys.stdin.isatty()
