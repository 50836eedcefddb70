"""`rig view`'s server answers only requests that name it: real HTTP requests to 127.0.0.1
with forged ``Host`` and ``Origin`` headers (DNS rebinding) are refused without the page."""

from __future__ import annotations

import http.client
import threading
from collections.abc import Iterator

import pytest

from rig.view.serve import make_server

PAGE = "<html>the viewer</html>"


@pytest.fixture(scope="module")
def port() -> Iterator[int]:
    server = make_server(PAGE)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server.server_address[1]
    server.shutdown()
    server.server_close()
    thread.join(timeout=10)


def get(port: int, headers: list[tuple[str, str]]) -> tuple[int, bytes]:
    """A GET with exactly ``headers`` (no Host added by http.client)."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        conn.putrequest("GET", "/", skip_host=True, skip_accept_encoding=True)
        for name, value in headers:
            conn.putheader(name, value)
        conn.endheaders()
        response = conn.getresponse()
        return response.status, response.read()
    finally:
        conn.close()


@pytest.mark.parametrize("host", ["127.0.0.1:{port}", "localhost:{port}", "LOCALHOST:{port}"])
def test_its_own_address_gets_the_page(port: int, host: str) -> None:
    assert get(port, [("Host", host.format(port=port))]) == (200, PAGE.encode())


def test_its_own_origin_gets_the_page(port: int) -> None:
    headers = [("Host", f"127.0.0.1:{port}"), ("Origin", f"http://127.0.0.1:{port}")]
    assert get(port, headers) == (200, PAGE.encode())


@pytest.mark.parametrize(
    "host",
    [
        "evil.example:{port}",  # a rebound name: the browser sends the attacker's host
        "evil.example",
        "127.0.0.1",  # no port
        "127.0.0.1:{other}",
        "127.0.0.1.evil.example:{port}",
        "0.0.0.0:{port}",
        "",
    ],
)
def test_a_forged_host_is_refused(port: int, host: str) -> None:
    status, body = get(port, [("Host", host.format(port=port, other=port + 1))])
    assert status == 421 and b"Host" in body and PAGE.encode() not in body


def test_no_host_or_two_hosts_are_refused(port: int) -> None:
    assert get(port, [])[0] == 421
    good = ("Host", f"127.0.0.1:{port}")
    assert get(port, [good, ("Host", "evil.example")])[0] == 421


@pytest.mark.parametrize(
    "origin",
    ["http://evil.example:{port}", "http://evil.example", "null", "https://127.0.0.1:{port}",
     "http://127.0.0.1:{other}"],
)
def test_a_forged_origin_is_refused(port: int, origin: str) -> None:
    headers = [("Host", f"127.0.0.1:{port}"), ("Origin", origin.format(port=port, other=port + 1))]
    status, body = get(port, headers)
    assert status == 403 and PAGE.encode() not in body
