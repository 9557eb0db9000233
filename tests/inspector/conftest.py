"""The inspector's tests mirror ``inspector/``; this file's folder holds the fake runs shared
across its subfolders (``fake_runs``), which pytest makes importable by loading it."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest
import viser


@pytest.fixture(scope="module")
def viser_server() -> Iterator[viser.ViserServer]:
    """A real viser server on a free loopback port, without a browser: what the panels and
    layers draw into."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    srv = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    yield srv
    srv.stop()
