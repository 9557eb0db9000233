"""Loading, as a person sees it (issue 19): the controls are disabled (the button rows hidden)
until there is something to step, a progress bar runs meanwhile, and the Files tab names the
log and route loaded, also from outside the data folders. In Chromium."""

from __future__ import annotations

import re
import shutil
import threading
from pathlib import Path

from _browser import free_port
from _browser import wait_until as _wait

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "monaco_tunnel.mcap"
ROUTE = REPO / "sample_logs" / "monaco_tunnel.route.geojson"


def test_controls_wait_for_the_session_and_the_files_tab_names_it(browser, tmp_path):
    from inspector.cli.serve import open_first, start

    # outside any data folder, and opened slowly enough to see the page before it loads
    log = shutil.copy(LOG, tmp_path / "elsewhere.mcap")
    route = shutil.copy(ROUTE, tmp_path / "elsewhere.route.geojson")
    release = threading.Event()
    (tmp_path / "empty").mkdir()
    server, controller, app = start(
        host="127.0.0.1", port=free_port(), data_dirs=[tmp_path / "empty"]
    )
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.set_default_timeout(90_000)
    try:
        opener = controller._opener

        def slow_open(log_path, route_path, progress, route_feature, topics):
            progress(0.1)
            release.wait(30)
            return opener(log_path, route_path, progress, route_feature, topics)

        controller._opener = slow_open
        page.goto(f"http://127.0.0.1:{server.get_port()}")
        _wait(lambda: "nothing loaded" in page.inner_text("body"), what="the empty page")
        open_first(controller, Path(log), Path(route))
        _wait(lambda: "loading elsewhere.mcap" in page.inner_text("body"), what="the progress")
        assert "%)" in page.inner_text("body")
        play = page.get_by_role("button", name="play", exact=True)
        assert play.is_disabled()
        assert page.get_by_role("slider").count() == 0  # viser draws a disabled slider thumbless
        assert page.get_by_role("button", name="rejected ›").count() == 0
        page.screenshot(path=str(tmp_path / "loading.png"))
        release.set()
        _wait(lambda: "match attempts" in page.inner_text("body"), 240, "the session")
        _wait(lambda: not play.is_disabled(), 20, "the controls to be enabled")
        assert page.get_by_role("slider").count() >= 1
        page.get_by_role("button", name="rejected ›").first.wait_for()
        page.get_by_role("tab", name="Files").click()
        body = " ".join(page.inner_text("body").split())  # the name and path on two lines
        assert "Loaded: log elsewhere.mcap" in body and str(tmp_path) in body
        assert "route elsewhere.route.geojson" in body
    finally:
        release.set()
        page.close()
        app.close()
        controller.close()
        server.stop()


def test_long_paths_in_the_files_tab_wrap_within_the_panel(browser, tmp_path):
    """A log and route of long names deep in long folders: the names and their full paths
    (a line beneath each name) stay inside the panel, and so do the names in the status line
    (they ran off its right edge, the paths cut)."""
    from _browser import served, session_page

    deep = tmp_path.joinpath(
        "fleet_recordings_2026",
        "vehicle_0042_highway_a8_munich_stuttgart",
        "session_2026-11-20T08-15-33Z_tunnel_survey",
    )
    deep.mkdir(parents=True)
    stem = "monaco_tunnel_drive_with_a_long_descriptive_name"
    log = Path(shutil.copy(LOG, deep / f"{stem}.mcap"))
    route = Path(shutil.copy(ROUTE, deep / f"{stem}.route.geojson"))
    with served(log, route) as (server, _, app):
        page, _ = session_page(browser, server, app, {"width": 1400, "height": 900})
        page.get_by_text("Legend").first.click()
        page.get_by_role("tab", name="Files").click()
        loaded = page.locator("div", has_text=re.compile(r"^Loaded:")).last
        loaded.wait_for()
        text = loaded.inner_text()
        assert f"{stem}.mcap" in text and str(log) in text.replace("\n", "")
        assert str(route) in text.replace("\n", "")
        status = page.locator("div", has_text=re.compile(f"^{stem}")).last
        for block in (loaded, status):
            overrun = block.evaluate(
                "el => Math.max(...[...el.querySelectorAll('*')].map("
                "c => c.getBoundingClientRect().right)) - el.getBoundingClientRect().right"
            )
            assert overrun <= 1, (overrun, block.inner_text()[:80])
        page.screenshot(path=str(tmp_path / "files_long_paths.png"))
        page.close()
