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
