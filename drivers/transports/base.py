"""The transport contract: bytes in, bytes out, with timeouts and a DEBUG log of every exchange.

Modelled on pymeasure's adapters: the public ``write``/``read`` log and delegate to private
``_write``/``_read`` that subclasses implement, so logging, secret redaction and "device not
answering" errors live in one place and every transport (and the scripted test transport)
behaves the same.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from types import TracebackType
from typing import Any

from core.errors import RigError

log = logging.getLogger("drivers.transport")

SECRET_KEYS = frozenset({"local_key", "key", "password", "token", "secret", "api_key"})


def redact(spec: Mapping[str, Any]) -> dict[str, Any]:
    """Copy of a profile section with secret values (Tuya local keys, passwords) masked."""
    out: dict[str, Any] = {}
    for key, value in spec.items():
        if key in SECRET_KEYS:
            out[key] = "***"
        elif isinstance(value, Mapping):
            out[key] = redact(value)
        else:
            out[key] = value
    return out


class NotAnsweringError(RigError):
    """The device stayed silent past its timeout."""


class Transport(ABC):
    """A byte channel to one device. ``read`` returns fewer bytes than asked on timeout."""

    kind = "transport"

    def __init__(self, address: str, timeout_s: float = 1.0, secrets: Sequence[bytes] = ()):
        self.address = address
        self.timeout_s = timeout_s
        self._secrets = tuple(s for s in secrets if s)
        self.closed = False

    # -- public API: logs, then calls the private implementation --------------------------
    def write(self, data: bytes) -> None:
        data = bytes(data)
        log.debug("%s %s <- %s", self.kind, self.address, self._show(data))
        self._write(data)

    def read(self, size: int) -> bytes:
        data = bytes(self._read(size))
        log.debug("%s %s -> %s", self.kind, self.address, self._show(data) if data else "(nothing)")
        return data

    def read_exactly(self, size: int, what: str = "a reply") -> bytes:
        """Read ``size`` bytes or raise NotAnsweringError once a read comes back empty."""
        out = bytearray()
        while len(out) < size:
            chunk = self.read(size - len(out))
            if not chunk:
                raise self.not_answering(what, got=bytes(out))
            out += chunk
        return bytes(out)

    def read_until(
        self, terminator: bytes = b"\n", max_size: int = 4096, what: str = "a reply"
    ) -> bytes:
        """Read up to and including ``terminator``; each byte may take up to the timeout."""
        out = bytearray()
        while not out.endswith(terminator):
            if len(out) >= max_size:
                raise RigError(
                    f"{self.kind} {self.address} sent {max_size} bytes without {terminator!r}",
                    "the device speaks another protocol: check the driver named in the profile",
                )
            chunk = self._read(1)
            if not chunk:
                raise self.not_answering(what, got=bytes(out))
            out += chunk
        log.debug("%s %s -> %s", self.kind, self.address, self._show(bytes(out)))
        return bytes(out)

    def flush_input(self) -> None:
        """Drop unread bytes (stale replies, boot banners) before a query."""
        self._flush_input()

    def not_answering(self, what: str, got: bytes = b"") -> NotAnsweringError:
        partial = f" (got only {self._show(got)})" if got else ""
        return NotAnsweringError(
            f"{self.kind} device {self.address} did not answer within {self.timeout_s:g} s "
            f"while waiting for {what}{partial}",
            "check that it is powered and plugged in, that the profile names the right "
            "port/address and driver, and that no other program holds it",
        )

    def describe(self) -> dict[str, Any]:
        return {"type": self.kind, "address": self.address, "timeout_s": self.timeout_s}

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._close()

    def __enter__(self) -> Transport:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- what each transport implements ----------------------------------------------------
    @abstractmethod
    def _write(self, data: bytes) -> None: ...

    @abstractmethod
    def _read(self, size: int) -> bytes: ...

    def _flush_input(self) -> None:
        return None

    def _close(self) -> None:
        return None

    def _show(self, data: bytes) -> str:
        """Hex for the log, with secret byte strings masked."""
        text = data.hex(" ")
        for secret in self._secrets:
            text = text.replace(secret.hex(" "), "<secret>")
        if len(data) <= 200 and all(32 <= b < 127 or b in (10, 13) for b in data):
            shown = data.decode("ascii").replace("\n", "\\n").replace("\r", "\\r")
            for secret in self._secrets:
                shown = shown.replace(secret.decode("latin-1"), "<secret>")
            return f"{text}  '{shown}'"
        return text
