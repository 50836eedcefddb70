"""TCP sockets (Wi-Fi bulbs such as Magic Home on port 5577)."""

from __future__ import annotations

import socket

from core.errors import RigError
from drivers.transports.base import Transport


class TcpTransport(Transport):
    kind = "tcp"

    def __init__(self, host: str, port: int, timeout_s: float = 2.0) -> None:
        super().__init__(f"{host}:{port}", timeout_s)
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout_s)
        except TimeoutError as error:
            raise RigError(
                f"{host}:{port} did not accept a connection within {timeout_s:g} s",
                "check the device is powered and on this network (its IP may have changed)",
            ) from error
        except OSError as error:
            raise RigError(
                f"cannot connect to {host}:{port}: {error.strerror or error}",
                "check the IP address and port in the profile and that the device is on",
            ) from error
        self._sock.settimeout(timeout_s)

    def _write(self, data: bytes) -> None:
        try:
            self._sock.sendall(data)
        except TimeoutError as error:
            raise self.not_answering("the send to finish") from error
        except OSError as error:
            raise RigError(f"connection to {self.address} failed: {error}", "reconnect") from error

    def _read(self, size: int) -> bytes:
        try:
            data = self._sock.recv(size)
        except TimeoutError:
            return b""
        except OSError as error:
            raise RigError(f"connection to {self.address} failed: {error}", "reconnect") from error
        if not data:
            raise RigError(
                f"{self.address} closed the connection",
                "the device may allow only one client: close its phone app and try again",
            )
        return data

    def _flush_input(self) -> None:
        self._sock.setblocking(False)
        try:
            while self._sock.recv(4096):
                pass
        except (BlockingIOError, OSError):
            pass
        finally:
            self._sock.settimeout(self.timeout_s)

    def _close(self) -> None:
        self._sock.close()
