"""The monaco sample with its route drawn 100 m north of the road (``json`` of the bundled
route, every latitude moved 0.0009 deg), in headless Chromium: near enough to be opened, too
far for any route update. The status line must say that the route is too far from the vehicle
at the outage's start and that the approach measured nothing, not that a map bias of 0.0 m
was found not significant. With ROUTEFUSE_UPDATE_SCREENSHOT=1 the screenshot replaces
docs/far_route.png."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from _browser import panel_screenshot, route_moved_north, served, session_page

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 1400, "height": 1100}


def test_a_route_too_far_for_any_update_is_named_on_the_page(browser, tmp_path):
    route = route_moved_north(
        REPO / "sample_logs" / "monaco_tunnel.route.geojson",
        0.0009,
        tmp_path / "monaco_north.route.geojson",
    )
    with served(REPO / "sample_logs" / "monaco_tunnel.mcap", route) as (server, controller, app):
        run = controller.session.proposed
        assert not any(m.accepted for m in run.matches)
        (line,) = [w for w in run.warnings if w.startswith("the route is ")]
        page, view = session_page(browser, server, app, VIEWPORT)
        text = page.inner_text("body")
        assert line in text, text[:2000]
        assert "nothing measured (too little GNSS-good driving before it" in text
        assert "0.0 m ahead" not in text
        shot = tmp_path / "far_route.png"
        view.seek(120.0)
        panel_screenshot(page, shot)
        page.close()
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(shot, REPO / "docs" / "far_route.png")
