"""Serve one page on the loopback interface only, until Ctrl-C.

Binding to 127.0.0.1 keeps other machines out, but not other web pages in the user's browser:
a page from a name that an attacker re-points at 127.0.0.1 (DNS rebinding) would be same-origin
with it. So every request must name this server in ``Host`` (and, when the browser sends one,
in ``Origin``); anything else is refused without the page.
"""

from __future__ import annotations

import http.server
import threading
import webbrowser
from collections.abc import Callable

LOOPBACK = "127.0.0.1"
LOOPBACK_NAMES = (LOOPBACK, "localhost")  # what a browser on this machine may call it


def make_server(page: str, port: int = 0) -> http.server.ThreadingHTTPServer:
    """A server bound to 127.0.0.1 (``port`` 0: a free one) answering every GET that names it
    in ``Host`` (and ``Origin``, when given) with ``page``: 421 for another host, 403 for
    another origin."""
    body = page.encode()
    hosts: set[str] = set()  # filled once the port is known

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            refusal = self._refusal()
            if refusal is not None:
                self._send(*refusal)
                return
            self._send(200, body, "text/html; charset=utf-8")

        def _refusal(self) -> tuple[int, bytes, str] | None:
            given = self.headers.get_all("Host") or []
            if len(given) != 1 or given[0].strip().lower() not in hosts:
                return 421, b"rig view: wrong Host; open the address rig printed\n", "text/plain"
            origins = self.headers.get_all("Origin") or []
            if origins and (len(origins) != 1 or origins[0].strip().lower()
                            not in {f"http://{h}" for h in hosts}):
                return 403, b"rig view: requests from other pages are refused\n", "text/plain"
            return None

        def _send(self, status: int, content: bytes, kind: str) -> None:
            self.send_response(status)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(content)))
            self.end_headers()
            self.wfile.write(content)

        def log_message(self, format: str, *args: object) -> None:  # quiet by default
            return

    server = http.server.ThreadingHTTPServer((LOOPBACK, port), Handler)
    hosts.update(f"{name}:{server.server_port}" for name in LOOPBACK_NAMES)
    return server


def serve(page: str, port: int, open_browser: bool, announce: Callable[[str], None]) -> None:
    server = make_server(page, port)
    url = f"http://{LOOPBACK}:{server.server_address[1]}/"
    announce(url)
    if open_browser:
        threading.Timer(0.5, webbrowser.open, args=(url,)).start()
    try:
        server.serve_forever()
    finally:
        server.server_close()
