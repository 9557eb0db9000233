"""Debian Chromium for the browser tests: where it is, the flags this machine's closed network
needs (without the background-networking ones Chromium floods it with refused connections), a
free loopback port, an in-process inspector server and a polling wait."""

from __future__ import annotations

import json
import socket
import time
from contextlib import contextmanager
from pathlib import Path

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def free_port() -> int:
    """A loopback port nobody listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(predicate, timeout: float = 30.0, what="condition"):
    """``predicate()``'s first truthy value, polled every 0.1 s; an AssertionError naming
    ``what`` (a string, or a callable giving one at the time) past ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what() if callable(what) else what}")


def route_moved_north(route: Path, dlat_deg: float, out: Path) -> Path:
    """``route`` (GeoJSON) with every latitude moved ``dlat_deg`` (0.00009 deg is about 10 m),
    written to ``out``: a map drawn off the road driven."""

    def move(c):
        if isinstance(c[0], float | int):
            return [c[0], c[1] + dlat_deg, *c[2:]]
        return [move(x) for x in c]

    data = json.loads(route.read_text(encoding="utf-8"))
    for feature in data["features"]:
        geometry = feature["geometry"]
        feature["geometry"] = {**geometry, "coordinates": move(geometry["coordinates"])}
    out.write_text(json.dumps(data), encoding="utf-8")
    return out


@contextmanager
def served(log: Path | None = None, route: Path | None = None, **options):
    """An in-process inspector on a free loopback port, its first log loaded (when given);
    yields ``(server, controller, app)`` and stops them afterwards."""
    from inspector.cli.serve import start

    options.setdefault("data_dirs", [])
    server, controller, app = start(
        host="127.0.0.1", port=free_port(), log=log, route=route, **options
    )
    try:
        if log is not None:
            assert controller.wait_idle(300), "the log did not load"
            assert controller.session is not None
        yield server, controller, app
    finally:
        app.close()
        controller.close()
        server.stop()


def session_page(browser, server, app, viewport):
    """A page on the served session once its status line is up, and the app's view of it."""
    page = browser.new_page(viewport=viewport)
    page.set_default_timeout(90_000)
    page.goto(f"http://127.0.0.1:{server.get_port()}")
    wait_until(lambda: "match attempts" in page.inner_text("body"), 60, "the session")
    view = wait_until(lambda: app.views(), 10, "the page's view")[0]
    return page, view


def panel_screenshot(page, path: Path) -> None:
    """The page with the legend folded (the gate table shows below it) and no notices (the
    "software WebGL" one) over it."""
    page.get_by_text("Legend").first.click()
    close = page.locator(".mantine-Notification-closeButton")
    for k in range(close.count()):
        close.nth(k).dispatch_event("click")
    time.sleep(2.0)
    page.screenshot(path=str(path))
