"""Refuse websocket connections from other web pages (cross-site WebSocket hijacking).

A browser lets any page the user visits open ``ws://127.0.0.1:PORT``; what protects a local
server is the ``Origin`` header the browser sends with the handshake, and viser does not look at
it. Its server is built on the ``websockets`` library, whose ``serve(origins=...)`` refuses a
handshake from any other origin with HTTP 403. viser does not pass that option, so
:func:`install` wraps ``websockets.asyncio.server.serve`` once per process to add it, computed
from the address the server actually binds (viser moves to the next port when one is busy).

Accepted: ``http://HOST:PORT`` for the bound host, its ``localhost``/``127.0.0.1``/``[::1]``
twins when it is a loopback address, and every origin named with ``--allow-origin``; and a
handshake without an ``Origin`` header, which no browser sends (scripts and tests do).
"""

from __future__ import annotations

import functools
import ipaddress
import re
import threading
from collections.abc import Callable, Iterable
from typing import Any
from urllib.parse import urlsplit

import websockets.asyncio.server as ws_server

LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")

_lock = threading.Lock()
_extra_origins: frozenset[str] = frozenset()
_installed = False


def normalise_origin(text: str) -> str:
    """``scheme://host[:port]`` in lower case, as a browser sends it; ValueError otherwise."""
    parts = urlsplit(text.strip())
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError(f"{text!r} is not an origin (expected http://HOST:PORT)")
    if parts.path not in ("", "/") or parts.query or parts.fragment or parts.username:
        raise ValueError(f"{text!r} is not an origin: only scheme, host and port")
    host = parts.hostname.lower()
    if ":" in host:
        host = f"[{host}]"
    port = f":{parts.port}" if parts.port is not None else ""
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


def install(extra_origins: Iterable[str] = ()) -> None:
    """Make every websocket server this process starts from now on check ``Origin``.

    Idempotent; the extra origins of the latest call apply (the inspector starts one server)."""
    global _extra_origins, _installed
    with _lock:
        _extra_origins = frozenset(normalise_origin(o) for o in extra_origins)
        if _installed:
            return
        original: Callable[..., Any] = ws_server.serve

        @functools.wraps(original)
        def serve(handler: Any, host: Any = None, port: Any = None, **kwargs: Any) -> Any:
            if kwargs.get("origins") is None and isinstance(port, int):
                kwargs["origins"] = origin_rules(str(host or "127.0.0.1"), port, _extra_origins)
            return original(handler, host, port, **kwargs)

        ws_server.serve = serve  # type: ignore[misc,assignment]  # the documented hook is missing in viser
        _installed = True
