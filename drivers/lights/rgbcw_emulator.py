"""A Python twin of the reference firmware (docs/firmware/rgbcw_controller.ino).

Used by tests and for trying the tool without a board: ``serve_pty()`` gives a pseudo-terminal
path that the real serial driver opens with pyserial, exactly as it would open /dev/ttyACM0.
"""

from __future__ import annotations

import os
import select
import sys
import threading
import tty
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

FIRMWARE = "1.0.0"
MODEL = "rig-rgbcw"
PWM_MAX = 4095  # 12-bit PWM as on the reference board
MAX_LINE = 120  # the firmware's line buffer


class RgbcwEmulator:
    """Answers one command line at a time, like the firmware's ``handleLine``."""

    def __init__(
        self, channels: Sequence[str] = ("r", "g", "b", "c", "w"), serial: str = "EMU0001"
    ):
        self.channels = tuple(channels)
        self.serial = serial
        self.duty = {c: 0 for c in self.channels}  # PWM counts, what the LEDs get
        self.lines: list[str] = []

    @property
    def levels(self) -> dict[str, float]:
        return {c: d / PWM_MAX for c, d in self.duty.items()}

    def respond(self, line: str) -> str:
        line = line.strip()
        self.lines.append(line)
        if not line:
            return ""
        if len(line) > MAX_LINE:
            return "ERR line too long"
        command, _, rest = line.partition(" ")
        if command == "ID?":
            return (
                f"ID model={MODEL} fw={FIRMWARE} serial={self.serial} "
                f"channels={','.join(self.channels)} pwm_bits=12"
            )
        if command == "OFF":
            self.duty = {c: 0 for c in self.channels}
            return "OK"
        if command == "GET?":
            return "LEVELS " + " ".join(f"{c}={d / PWM_MAX:.4f}" for c, d in self.duty.items())
        if command == "SET":
            new = {c: 0 for c in self.channels}
            for word in rest.split():
                name, sep, value = word.partition("=")
                if not sep or name not in new:
                    return f"ERR unknown channel {name}"
                try:
                    level = float(value)
                except ValueError:
                    return f"ERR bad value {value}"
                if not 0.0 <= level <= 1.0:
                    return f"ERR out of range {name}={value}"
                new[name] = int(level * PWM_MAX + 0.5)  # as the firmware rounds
            self.duty = new
            return "OK"
        return f"ERR unknown command {command}"

    def serve(self, fd: int, stop: threading.Event) -> None:
        """Read lines from ``fd`` and write replies until ``stop`` is set."""
        buffer = b""
        os.write(fd, b"READY\n")
        while not stop.is_set():
            ready, _, _ = select.select([fd], [], [], 0.05)
            if not ready:
                continue
            try:
                chunk = os.read(fd, 256)
            except OSError:  # the other end closed
                return
            buffer += chunk
            while b"\n" in buffer:
                raw, buffer = buffer.split(b"\n", 1)
                reply = self.respond(raw.decode("ascii", errors="replace"))
                if reply:
                    os.write(fd, reply.encode("ascii") + b"\n")


@contextmanager
def serve_pty(emulator: RgbcwEmulator | None = None) -> Iterator[tuple[str, RgbcwEmulator]]:
    """Run an emulator on a new pseudo-terminal; yields (device path, emulator)."""
    emulator = emulator or RgbcwEmulator()
    master, slave = os.openpty()
    path = os.ttyname(slave)
    tty.setraw(slave)  # no echo or line editing before the driver configures the port
    stop = threading.Event()
    thread = threading.Thread(target=emulator.serve, args=(master, stop), daemon=True)
    thread.start()
    try:
        yield path, emulator
    finally:
        stop.set()
        thread.join(timeout=2)
        os.close(master)
        os.close(slave)


def serve_stdio(emulator: RgbcwEmulator | None = None) -> None:
    """Answer on stdin/stdout until stdin closes: a light behind the ``subprocess`` transport
    (``command: [python, -m, drivers.lights.rgbcw_emulator]``), for trying a bridge setup."""
    emulator = emulator or RgbcwEmulator()
    out = sys.stdout.buffer
    out.write(b"READY\n")
    out.flush()
    for raw in sys.stdin.buffer:
        reply = emulator.respond(raw.decode("ascii", errors="replace"))
        if reply:
            out.write(reply.encode("ascii") + b"\n")
            out.flush()


if __name__ == "__main__":
    serve_stdio()
