"""A page of another origin cannot open the inspector's websocket; its own page can."""

from __future__ import annotations

import socket

import pytest
import viser
import websockets.exceptions
from websockets.sync.client import connect

from inspector import origin_guard


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def server() -> viser.ViserServer:
    origin_guard.install(["http://inspector.lan:9000"])
    srv = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    yield srv
    srv.stop()


def _handshake(port: int, origin: str | None) -> int:
    """The HTTP status of a websocket handshake sent with ``origin`` (101 when accepted)."""
    kwargs = {} if origin is None else {"origin": origin}
    try:
        with connect(f"ws://127.0.0.1:{port}", open_timeout=5, **kwargs) as ws:
            return 101 if ws.protocol is not None else 0
    except websockets.exceptions.InvalidStatus as exc:
        return exc.response.status_code


@pytest.mark.parametrize(
    "origin",
    ["http://evil.example", "http://127.0.0.1:1", "https://127.0.0.1.evil.example", "null"],
)
def test_other_origins_are_refused(server: viser.ViserServer, origin: str) -> None:
    assert _handshake(server.get_port(), origin) == 403


def test_own_origin_and_its_loopback_twins_connect(server: viser.ViserServer) -> None:
    port = server.get_port()
    for host in ("127.0.0.1", "localhost", "[::1]"):
        assert _handshake(port, f"http://{host}:{port}") == 101
    assert _handshake(port, "http://inspector.lan:9000") == 101
    assert _handshake(port, None) == 101


def test_origin_rules_for_a_system_chosen_port() -> None:
    rules = origin_guard.origin_rules("127.0.0.1", 0)
    pattern = next(r for r in rules if hasattr(r, "fullmatch"))
    assert pattern.fullmatch("http://localhost:43121")
    assert not pattern.fullmatch("http://localhost.evil.example:43121")
    assert not pattern.fullmatch("http://evil.example:80")


@pytest.mark.parametrize("text", ["evil.example", "http://a/b", "ftp://x:1", "http://u@x:1"])
def test_a_malformed_allowed_origin_is_refused(text: str) -> None:
    with pytest.raises(ValueError, match="origin"):
        origin_guard.normalise_origin(text)


def test_a_named_origin_is_normalised() -> None:
    assert (
        origin_guard.normalise_origin("HTTP://Inspector.LAN:9000/") == "http://inspector.lan:9000"
    )


@pytest.mark.parametrize(
    ("text", "origin"),
    [
        ("http://inspector.lan:80", "http://inspector.lan"),
        ("https://inspector.lan:443/", "https://inspector.lan"),
        ("https://inspector.lan:80", "https://inspector.lan:80"),
    ],
)
def test_a_default_port_is_left_out_as_browsers_leave_it_out(text: str, origin: str) -> None:
    assert origin_guard.normalise_origin(text) == origin


def test_with_a_system_chosen_port_only_that_port_connects() -> None:
    """``--port 0``: the port is known once bound, and a page served by another local server
    (a notebook, a dev server) must not drive the inspector."""
    origin_guard.install()
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        port = srv.get_port()
        assert port != 0
        assert _handshake(port, f"http://127.0.0.1:{port}") == 101
        assert _handshake(port, f"http://localhost:{port}") == 101
        for other in (3000, 8888, port + 1):
            assert _handshake(port, f"http://127.0.0.1:{other}") == 403
            assert _handshake(port, f"http://localhost:{other}") == 403
    finally:
        srv.stop()


def _get(port: int, path: str) -> tuple[int, dict[str, str], bytes]:
    import urllib.error
    import urllib.request

    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=5) as r:
            return r.status, dict(r.headers.items()), r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, dict(exc.headers.items()), exc.read()


def test_the_page_may_connect_to_its_own_server_only_and_be_framed_by_none(
    server: viser.ViserServer,
) -> None:
    status, headers, body = _get(server.get_port(), "/")
    assert status == 200 and b"<html" in body.lower()
    policy = headers["Content-Security-Policy"]
    assert "connect-src 'self'" in policy
    assert "frame-ancestors 'none'" in policy
    assert headers["X-Frame-Options"] == "DENY"


@pytest.mark.parametrize(
    "query",
    [
        "?websocket=ws://evil.example:9999",
        "?websocket=ws%3A%2F%2F127.0.0.1%3A9999",
        "?x=1&playbackPath=http://evil.example/rec.viser",
        "?websocket=",
    ],
)
def test_a_page_address_pointing_the_client_elsewhere_is_refused(
    server: viser.ViserServer, query: str
) -> None:
    """viser's page connects to whatever ``?websocket=`` names and shows that server's HTML in
    the inspector's origin, where its script could drive the real inspector."""
    status, headers, body = _get(server.get_port(), f"/{query}")
    assert status == 400
    assert b"own server" in body
    assert headers["X-Frame-Options"] == "DENY"


def test_the_export_recorder_refuses_other_origins() -> None:
    from inspector.export.replay import headless_server

    with headless_server() as srv:
        port = srv.get_port()
        assert _handshake(port, "http://evil.example") == 403
        assert _handshake(port, None) == 101
