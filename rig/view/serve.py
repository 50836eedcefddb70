"""Serve one page on the loopback interface only, until Ctrl-C."""

from __future__ import annotations

import http.server
import threading
import webbrowser
from collections.abc import Callable


def make_server(page: str, port: int = 0) -> http.server.ThreadingHTTPServer:
    """A server bound to 127.0.0.1 (``port`` 0: a free one) answering every GET with ``page``."""
    body = page.encode()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, format: str, *args: object) -> None:  # quiet by default
            return

    return http.server.ThreadingHTTPServer(("127.0.0.1", port), Handler)


def serve(page: str, port: int, open_browser: bool, announce: Callable[[str], None]) -> None:
    server = make_server(page, port)
    url = f"http://127.0.0.1:{server.server_address[1]}/"
    announce(url)
    if open_browser:
        threading.Timer(0.5, webbrowser.open, args=(url,)).start()
    try:
        server.serve_forever()
    finally:
        server.server_close()
