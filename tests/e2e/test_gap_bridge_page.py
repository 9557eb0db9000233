"""Corpus drive 16 (``routefuse simulate --stress 16``) in headless Chromium: a 48 s IMU gap
inside the long tunnel, bridged along the route (``extensions.gap_route_bridge``). The page must
say so where a user looks: the status line's warning and the Match tab of the attempt the gap
was bridged before. With ROUTEFUSE_UPDATE_SCREENSHOT=1 its screenshot replaces
docs/gap_bridge.png."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from _browser import panel_screenshot, served, session_page, wait_until

from inspector.cli.main import main

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 1400, "height": 1250}


def test_bridged_gap_on_the_page(browser, tmp_path):
    assert main(["simulate", "--stress", "16", "--out", str(tmp_path)]) == 0
    bag, route = tmp_path / "stress_16.mcap", tmp_path / "stress_16.route.geojson"
    with served(bag, route) as (server, controller, app):
        session = controller.session
        matches = session.proposed.matches
        (i,) = [k for k, m in enumerate(matches) if "gap_bridge_end_s" in m.extra]
        m = matches[i]
        t_match = float(session.timeline.match_t[i])
        end = m.extra["gap_bridge_end_s"]

        page, view = session_page(browser, server, app, VIEWPORT)
        status = page.inner_text("body")
        line = f"IMU gap that ended at {end:.1f} s bridged along the route there: the wheels'"
        assert line in status, status[:1500]

        page.get_by_role("tab", name="Match").click()
        view.seek(t_match + 0.01)
        wait_until(lambda: f"Attempt #{i} (" in page.inner_text("body"), 20, "the attempt")
        text = page.inner_text("body")
        assert f"Before this attempt the IMU gap that ended at {end:.1f} s was bridged" in text
        assert "(extensions.gap_route_bridge)" in text, text[:3000]
        shot = tmp_path / "gap_bridge.png"
        panel_screenshot(page, shot)
        page.close()
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(shot, REPO / "docs" / "gap_bridge.png")
