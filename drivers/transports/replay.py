"""Transports for tests and diagnosis: a byte script to replay, and a recorder to make one.

``ScriptedTransport`` follows pymeasure's ``expected_protocol``: a list of
``(expected request bytes, reply bytes)``; any write that differs from the script, or any
exchange left unused when the ``with`` block ends, fails the test. ``RecordingTransport``
wraps a real transport and writes each exchange of a real session to JSONL in the same
shape, so a session with real hardware becomes a replayable script.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from types import TracebackType
from typing import Any, TextIO

from core.errors import RigError
from drivers.transports.base import Transport

Exchange = tuple[bytes | None, bytes | None]


class ScriptMismatch(AssertionError):
    """The driver did not send what the script expected (or left exchanges unused)."""


class ScriptedTransport(Transport):
    """Replays ``(request, reply)`` pairs. ``request=None`` is a read with no write before it;
    ``reply=None`` or ``b""`` means the device stays silent (the read times out)."""

    kind = "scripted"

    def __init__(self, exchanges: Iterable[Exchange], address: str = "script") -> None:
        super().__init__(address, timeout_s=0.0)
        self.exchanges: list[Exchange] = [
            (None if req is None else bytes(req), bytes(rep or b"")) for req, rep in exchanges
        ]
        self.position = 0
        self._written = b""
        self._replies = b""

    @classmethod
    def from_jsonl(cls, path: str | Path) -> ScriptedTransport:
        """Load a recording written by ``RecordingTransport``."""
        exchanges: list[Exchange] = []
        if not Path(path).is_file():
            raise RigError(f"recording {path} does not exist", "check the replay file's path")
        with open(path, encoding="utf-8") as handle:
            for number, line in enumerate(handle, 1):
                if not line.strip():
                    continue
                try:
                    item = json.loads(line)
                    request = None if item["request"] is None else bytes.fromhex(item["request"])
                    exchanges.append((request, bytes.fromhex(item["reply"])))
                except (ValueError, KeyError, TypeError) as error:
                    raise RigError(
                        f"{path}:{number} is not a recorded exchange ({error})",
                        'each line must be {"request": HEX or null, "reply": HEX}',
                    ) from error
        return cls(exchanges, address=str(path))

    def _write(self, data: bytes) -> None:
        self._written += data
        while self._written:
            if self.position >= len(self.exchanges):
                raise ScriptMismatch(
                    f"unexpected write {self._written.hex(' ')}: script is used up"
                )
            expected, reply = self.exchanges[self.position]
            if expected is None:
                raise ScriptMismatch(
                    f"exchange {self.position}: wrote {self._written.hex(' ')} but the script "
                    "expected a read with no request"
                )
            n = min(len(expected), len(self._written))
            if self._written[:n] != expected[:n]:
                first = next(i for i in range(n) if self._written[i] != expected[i])
                start = max(0, first - 8)
                raise ScriptMismatch(
                    f"exchange {self.position}: byte {first} differs "
                    f"(showing from byte {start})\n"
                    f"  expected {expected[start : start + 24].hex(' ')}\n"
                    f"  written  {self._written[start : start + 24].hex(' ')}"
                )
            if len(self._written) < len(expected):
                return
            self._written = self._written[len(expected) :]
            self._replies += reply or b""
            self.position += 1

    def _read(self, size: int) -> bytes:
        if not self._replies and self.position < len(self.exchanges):
            expected, reply = self.exchanges[self.position]
            if expected is None:
                self._replies += reply or b""
                self.position += 1
        out, self._replies = self._replies[:size], self._replies[size:]
        return out

    def _flush_input(self) -> None:
        if self._replies:
            raise ScriptMismatch(f"driver flushed unread reply bytes {self._replies.hex(' ')}")

    def assert_done(self) -> None:
        """Fail unless every exchange was used and every reply byte read."""
        problems = []
        if self._written:
            problems.append(f"partial write {self._written.hex(' ')} matches no whole request")
        if self.position < len(self.exchanges):
            left = self.exchanges[self.position :]
            shown = ", ".join(
                f"{'read' if req is None else req.hex(' ')} -> {rep.hex(' ') if rep else '-'}"
                for req, rep in left[:3]
            )
            problems.append(f"{len(left)} exchange(s) unused: {shown}")
        if self._replies:
            problems.append(f"reply bytes never read: {self._replies.hex(' ')}")
        if problems:
            raise ScriptMismatch("; ".join(problems))

    def __enter__(self) -> ScriptedTransport:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.assert_done()
        self.close()


class RecordingTransport(Transport):
    """Pass-through to ``inner`` that appends each exchange to a JSONL file."""

    kind = "recording"

    def __init__(self, inner: Transport, path: str | Path) -> None:
        super().__init__(inner.address, inner.timeout_s)
        self.inner = inner
        self.path = Path(path)
        try:
            self._file: TextIO = open(self.path, "a", encoding="utf-8")
        except OSError as error:
            raise RigError(
                f"cannot write the transport recording {self.path}: {error.strerror or error}",
                "fix the `record:` path in the profile (its folder must exist)",
            ) from error
        self._request: bytes | None = None
        self._reply = b""
        self._open = False

    def _flush_exchange(self) -> None:
        if self._open:
            record = {
                "request": None if self._request is None else self._request.hex(),
                "reply": self._reply.hex(),
            }
            self._file.write(json.dumps(record) + "\n")
            self._file.flush()
        self._request, self._reply, self._open = None, b"", False

    def _write(self, data: bytes) -> None:
        self._flush_exchange()
        self._request, self._open = data, True
        self.inner.write(data)

    def _read(self, size: int) -> bytes:
        data = self.inner.read(size)
        if data:
            self._open = True
            self._reply += data
        return data

    def _flush_input(self) -> None:
        self.inner.flush_input()

    def _close(self) -> None:
        self._flush_exchange()
        self._file.close()
        self.inner.close()

    def describe(self) -> dict[str, Any]:
        return {**self.inner.describe(), "recorded_to": str(self.path)}
