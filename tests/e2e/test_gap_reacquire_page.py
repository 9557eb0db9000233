"""Corpus drive 36 (``routefuse simulate --stress 36``) in headless Chromium: a 28 s IMU gap
inside the long tunnel hides an 18-20 deg turn of the road, and the route re-acquires the
heading after it (``extensions.gap_reacquire``). The page must say so where a user looks: the
status line's warning and the Match tab of the re-anchored attempt, which is ACCEPTED with
failed gates. With ROUTEFUSE_UPDATE_SCREENSHOT=1 its screenshot replaces
docs/gap_reacquire.png."""

from __future__ import annotations

import os
import re
import shutil
import time
from pathlib import Path

import pytest
from _browser import served, wait_until

from inspector.cli.main import main

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 1400, "height": 1250}


def test_re_acquired_heading_on_the_page(browser, tmp_path):
    assert main(["simulate", "--stress", "36", "--out", str(tmp_path)]) == 0
    bag, route = tmp_path / "stress_36.mcap", tmp_path / "stress_36.route.geojson"
    with served(bag, route) as (server, controller, app):
        session = controller.session
        matches = session.proposed.matches
        (i, *_) = [k for k, m in enumerate(matches) if "gap_end_s" in m.extra]
        m = matches[i]
        assert m.accepted and m.reanchored and m.failed_gates
        t_match = float(session.timeline.match_t[i])

        page = browser.new_page(viewport=VIEWPORT)
        page.set_default_timeout(90_000)
        page.goto(f"http://127.0.0.1:{server.get_port()}")
        wait_until(lambda: "match attempts" in page.inner_text("body"), 60, "the session")
        view = wait_until(lambda: app.views(), 10, "the page's view")[0]
        status = page.inner_text("body")
        assert f"heading re-acquired from the route at {t_match:.1f} s" in status, status[:1500]

        page.get_by_role("tab", name="Match").click()
        view.seek(t_match + 0.01)
        wait_until(lambda: f"Attempt #{i} of" in page.inner_text("body"), 20, "the attempt")
        text = page.inner_text("body")
        assert "ACCEPTED (re-anchored)" in text, text[:3000]
        assert re.search(r"rotation\s+[\d.]+\s+<= 15\.000\s+✗ FAILED", text), text[:3000]
        assert "the IMU gap that ended at" in text and "deg here)" in text
        page.get_by_text("Legend").first.click()
        close = page.locator(".mantine-Notification-closeButton")
        for k in range(close.count()):
            close.nth(k).dispatch_event("click")
        time.sleep(2.0)
        shot = tmp_path / "gap_reacquire.png"
        page.screenshot(path=str(shot))
        page.close()
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(shot, REPO / "docs" / "gap_reacquire.png")
