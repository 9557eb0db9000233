"""Refuse websocket connections from other web pages (cross-site WebSocket hijacking), and keep
the inspector's page from being framed or pointed at another server.

A browser lets any page the user visits open ``ws://127.0.0.1:PORT``; what protects a local
server is the ``Origin`` header the browser sends with the handshake, and viser does not look at
it. Its server is built on the ``websockets`` library, whose ``serve(origins=...)`` refuses a
handshake from any other origin with HTTP 403. viser does not pass that option, so
:func:`install` wraps ``websockets.asyncio.server.serve`` once per process to add it, computed
from the address the server actually binds (viser moves to the next port when one is busy).
The same wrapper checks each handshake's ``Origin`` again against the port the connection
arrived on, which a server asked for port 0 knows only once bound.

Accepted: ``http://HOST:PORT`` for the bound host, its ``localhost``/``127.0.0.1``/``[::1]``
twins when it is a loopback address, and every origin named with ``--allow-origin``; and a
handshake without an ``Origin`` header, which no browser sends (scripts and tests do).

The page viser serves would connect to any server a ``?websocket=`` in its address names, and
show that server's HTML as its own, in the inspector's origin, where a script can then drive
the real inspector; so such an address is refused, and every page is sent with a content
security policy that lets it connect to its own server only and be framed by no page
(``connect-src 'self'``, ``frame-ancestors 'none'``).
"""

from __future__ import annotations

import functools
import ipaddress
import re
import threading
from collections.abc import Callable, Iterable
from typing import Any
from urllib.parse import parse_qs, urlsplit

import websockets.asyncio.server as ws_server
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")
DEFAULT_PORTS = {"http": 80, "https": 443}
REDIRECTING_QUERY = ("websocket", "playbackPath")
"""viser client query parameters that make the page load another server or file"""
PAGE_HEADERS = {
    "Content-Security-Policy": "connect-src 'self' blob: data:; frame-ancestors 'none'",
    "X-Frame-Options": "DENY",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}
"""sent with every HTTP response: the page connects to its own server only, and no other
page may frame it (a click on another site landing on the inspector's buttons)"""

_lock = threading.Lock()
_extra_origins: frozenset[str] = frozenset()
_installed = False


def normalise_origin(text: str) -> str:
    """``scheme://host[:port]`` in lower case, the scheme's default port left out, as a browser
    sends it; ValueError otherwise."""
    parts = urlsplit(text.strip())
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError(f"{text!r} is not an origin (expected http://HOST:PORT)")
    if parts.path not in ("", "/") or parts.query or parts.fragment or parts.username:
        raise ValueError(f"{text!r} is not an origin: only scheme, host and port")
    host = parts.hostname.lower()
    if ":" in host:
        host = f"[{host}]"
    shown_port = parts.port is not None and parts.port != DEFAULT_PORTS[parts.scheme]
    port = f":{parts.port}" if shown_port else ""
    return f"{parts.scheme}://{host}{port}"


def _is_loopback(host: str) -> bool:
    if host in ("localhost", "[::1]"):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def allowed_origins(host: str, port: int, extra: Iterable[str] = ()) -> frozenset[str]:
    """The origins whose pages may connect to a server bound at ``host:port``."""
    shown = f"[{host}]" if ":" in host and not host.startswith("[") else host
    hosts = {shown}
    if _is_loopback(shown) or host in ("0.0.0.0", "::", ""):
        hosts.update(LOOPBACK_NAMES)
    return frozenset({f"http://{h}:{port}" for h in hosts} | set(extra))


def origin_rules(
    host: str, port: int, extra: Iterable[str] = ()
) -> list[str | re.Pattern[str] | None]:
    """``websockets``' ``origins`` for a server asked to bind ``host:port``: the exact origins,
    or, for port 0 (the system picks it, unknown here), any port of the allowed hosts."""
    rules: list[str | re.Pattern[str] | None] = [None]
    if port:
        return [*sorted(allowed_origins(host, port, extra)), *rules]
    hosts = {h.removesuffix(":0").removeprefix("http://") for h in allowed_origins(host, 0)}
    alternatives = "|".join(re.escape(h) for h in sorted(hosts))
    return [re.compile(rf"http://(?:{alternatives}):\d+"), *sorted(extra), *rules]


def install(extra_origins: Iterable[str] | None = None) -> None:
    """Make every websocket server this process starts from now on check ``Origin``.

    Idempotent; the extra origins of the latest call that names any (``None`` keeps them)
    apply (the inspector starts one server)."""
    global _extra_origins, _installed
    with _lock:
        if extra_origins is not None:
            _extra_origins = frozenset(normalise_origin(o) for o in extra_origins)
        if _installed:
            return
        original: Callable[..., Any] = ws_server.serve

        @functools.wraps(original)
        def serve(handler: Any, host: Any = None, port: Any = None, **kwargs: Any) -> Any:
            if kwargs.get("origins") is None and isinstance(port, int):
                bound = str(host or "127.0.0.1")
                kwargs["origins"] = origin_rules(bound, port, _extra_origins)
                kwargs["process_request"] = _guarded(kwargs.get("process_request"), bound)
            return original(handler, host, port, **kwargs)

        ws_server.serve = serve  # type: ignore[misc,assignment]  # the documented hook is missing in viser
        _installed = True


def _refused(status: int, text: str) -> Response:
    body = text.encode()
    headers = Headers({"Content-Type": "text/plain; charset=utf-8", **PAGE_HEADERS})
    headers["Content-Length"] = str(len(body))
    return Response(status, "Forbidden" if status == 403 else "Bad Request", headers, body)


def _guarded(process_request: Callable[..., Any] | None, host: str) -> Callable[..., Any]:
    """``process_request`` for ``websockets.serve``: a handshake's ``Origin`` checked against the
    port it arrived on; a page address that would point the client elsewhere refused; every
    page sent with :data:`PAGE_HEADERS`."""

    def guarded(connection: Any, request: Request) -> Response | None:
        if request.headers.get("Upgrade", "").lower() == "websocket":
            origin = request.headers.get("Origin")
            port = int(connection.local_address[1])
            if origin is not None and origin not in allowed_origins(host, port, _extra_origins):
                return _refused(403, "this page's origin may not connect to the inspector")
            return None
        query = parse_qs(urlsplit(request.path).query, keep_blank_values=True)
        if any(name in query for name in REDIRECTING_QUERY):
            return _refused(400, "the inspector's page connects only to its own server")
        response = process_request(connection, request) if process_request else None
        if isinstance(response, Response):
            for name, value in PAGE_HEADERS.items():
                response.headers[name] = value
        return response

    return guarded
