"""Compare two parameter sets in the live inspector (issue 19): pin the run as A, change a
parameter in the Parameters tab, and the Compare tab shows A, B and B - A, steps through the
attempts whose verdict changed with both gate tables, and A is drawn beside B. In Chromium,
clicking as a person does. With ROUTEFUSE_UPDATE_SCREENSHOT=1 its screenshot replaces
docs/inspector_compare.png (the README's)."""

from __future__ import annotations

import os
import re
import shutil
import time
from pathlib import Path

import pytest
from _browser import served
from _browser import wait_until as _wait

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "monaco_tunnel.mcap"
ROUTE = REPO / "sample_logs" / "monaco_tunnel.route.geojson"


@pytest.fixture(scope="module")
def session():
    with served(LOG, ROUTE) as running:
        yield running


def test_pin_change_and_step_the_changed_verdicts(browser, session, tmp_path):
    server, controller, app = session
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.set_default_timeout(90_000)
    try:
        page.goto(f"http://127.0.0.1:{server.get_port()}")
        _wait(lambda: "match attempts" in page.inner_text("body"), what="the session")
        view = app.views()[-1]
        page.get_by_role("tab", name="Compare").click()
        page.get_by_role("button", name="pin as A").click()
        _wait(lambda: "A is pinned" in page.inner_text("body"), what="the pin")
        # B: a tighter residual gate, moved on its slider as a person does (to its minimum)
        page.get_by_role("tab", name="Parameters").click()
        uid = page.locator("label", has_text=re.compile(r"^max_residual_m$")).first.get_attribute(
            "for"
        )
        thumb = page.locator(f"[id='{uid}'] [role='slider']")
        thumb.focus()
        thumb.press("Home")
        _wait(lambda: controller.params.gates.max_residual_m < 1.0, 10, "the parameter")
        assert controller.wait_idle(120)
        page.get_by_role("tab", name="Compare").click()
        _wait(lambda: "changed verdict" in page.inner_text("body"), 30, "the comparison")
        text = page.inner_text("body")
        n = int(re.search(r"(\d+) attempts changed verdict", text).group(1))
        assert n > 0
        assert re.search(r"match attempts.*\|", text) or "B - A" in text
        # step to the first changed attempt: both gate tables, A accepted, B refused
        page.get_by_role("button", name="changed ›").click()
        _wait(lambda: "Changed attempt 1 of" in page.inner_text("body"), 20, "the step")
        text = page.inner_text("body")
        assert "A (pinned)" in text and "B (on screen)" in text
        assert "ACCEPTED" in text and "REJECTED" in text and "✗ FAILED" in text
        assert view.compare.pinned is not None
        # the Plots tab overlays A's proposed run on B's
        page.get_by_role("tab", name="Plots").click()
        _wait(
            lambda: "A against B: position deviation from the route" in page.inner_text("body"),
            20,
            "the A-against-B plot",
        )
        assert "A (pinned)" in page.inner_text("body")
        page.screenshot(path=str(tmp_path / "plots_a_against_b.png"))
        page.get_by_role("tab", name="Compare").click()
        assert view.client.scene._handle_from_node_name.get("/routefuse_pinned_a/track")
        close = page.locator(".mantine-Notification-closeButton")
        for k in range(close.count()):
            close.nth(k).dispatch_event("click")  # the "software WebGL" notice covers the map
        time.sleep(1.5)
        shot = tmp_path / "inspector_compare.png"
        page.screenshot(path=str(shot))
        if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
            shutil.move(shot, REPO / "docs" / "inspector_compare.png")
    finally:
        page.close()
