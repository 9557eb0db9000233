"""A route file holding two lines, opened from the Files tab in headless Chromium as a person
does: the route file is picked, 'open' says the file has two lines (named, as text) and to
choose one under 'route line', the 'route line' dropdown offers them, line 1 is chosen, and
'open' runs on it. With ROUTEFUSE_UPDATE_SCREENSHOT=1 the screenshot of the Files tab with the
dropdown open replaces docs/route_line.png."""

from __future__ import annotations

import os
import re
import shutil
import time
from pathlib import Path

import pytest
from _browser import served, session_page, wait_until

from tests.inspector.fake_runs import HOSTILE_LINE, MONACO_LOG, MONACO_ROUTE, two_line_route

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 1400, "height": 1000}


def _pick(page, label: str, option: str) -> None:
    """Open the dropdown labelled ``label`` and click ``option`` in its list."""
    uid = page.locator("label", has_text=re.compile(f"^{re.escape(label)}$")).first
    page.locator(f"[id='{uid.get_attribute('for')}']").click()
    page.get_by_role("option", name=option, exact=True).click()


def _click(page, name: str) -> None:
    page.get_by_role("button", name=name, exact=True).first.click()


def test_a_two_line_route_opens_on_the_line_chosen_in_the_files_tab(browser, tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    log = Path(shutil.copy(MONACO_LOG, data / "monaco.mcap"))
    route = Path(shutil.copy(MONACO_ROUTE, data / "monaco.route.geojson"))
    two_line_route(data / "two.route.geojson")
    with served(log, route, data_dirs=[data]) as (server, controller, app):
        first = controller.session
        page, view = session_page(browser, server, app, VIEWPORT)
        dialogs: list[str] = []
        page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
        page.get_by_text("Legend").first.click()  # folded: the Files tab in view
        page.get_by_role("tab", name="Files").click()
        assert page.locator("label", has_text=re.compile("^route line$")).count() == 0

        _pick(page, "route file", "data/two.route.geojson")
        route_line = page.locator("label", has_text=re.compile("^route line$"))
        route_line.first.wait_for()  # offered once the file holds several lines
        _click(page, "open")
        wait_until(lambda: "Kept the previous session" in page.inner_text("body"), 60, "refusal")
        body = page.inner_text("body")
        assert (
            f"two.route.geojson: the file has 2 lines (0: {HOSTILE_LINE}, 1: east); choose one "
            "under 'route line' in the Files tab, then press 'open'"
        ) in body
        assert controller.session is first
        assert page.locator("img[src='x']").count() == 0 and not dialogs  # the name is text

        _pick(page, "route line", "1: east")
        wait_until(lambda: view.files.route_line.value == "1: east", 10, "the pick to arrive")
        shot = tmp_path / "route_line.png"
        uid = route_line.first.get_attribute("for")
        page.locator(f"[id='{uid}']").click()  # the list open, for the screenshot
        page.get_by_role("option", name=f"0: {HOSTILE_LINE}", exact=True).wait_for()
        page.mouse.move(300, 700)  # no hint tooltip over the dropdowns
        time.sleep(1.0)
        page.screenshot(path=str(shot))
        page.keyboard.press("Escape")
        _click(page, "open")
        wait_until(
            lambda: controller.session is not first and controller.session.route_feature == 1,
            240,
            "a run on line 1",
        )
        assert controller.session.inputs.route.name == "east"
        assert controller.session.route_name == "data/two.route.geojson"
        wait_until(lambda: "line 1: east" in page.inner_text("body"), 30, "the line named")
        assert page.locator("img[src='x']").count() == 0 and not dialogs
        page.close()
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(shot, REPO / "docs" / "route_line.png")
