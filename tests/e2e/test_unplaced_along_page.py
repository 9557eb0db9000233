"""Corpus drive 32 (``routefuse simulate --stress 32``: long tunnel, no odometer) in headless
Chromium: every route update of its outage is accepted and the trace sits on the route, while
the filter does not know within 100 m where along the road it is. The status line's warnings
must say so, whole. With ROUTEFUSE_UPDATE_SCREENSHOT=1 the screenshot replaces
docs/unplaced_along.png."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from _browser import panel_screenshot, served, session_page

from inspector.cli.main import main

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 1400, "height": 1100}


def test_an_accepted_trace_unknown_along_the_road_is_warned(browser, tmp_path):
    assert main(["simulate", "--stress", "32", "--out", str(tmp_path)]) == 0
    bag, route = tmp_path / "stress_32.mcap", tmp_path / "stress_32.route.geojson"
    with served(bag, route) as (server, controller, app):
        run = controller.session.proposed
        (line,) = [w for w in run.warnings if "route updates accepted, yet" in w]
        assert all(m.accepted for m in run.matches)
        page, view = session_page(browser, server, app, VIEWPORT)
        text = page.inner_text("body")
        assert line in text, text[:2000]
        assert "warnings about this log and its run" in text
        shot = tmp_path / "unplaced_along.png"
        view.seek(389.0)
        panel_screenshot(page, shot)
        page.close()
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(shot, REPO / "docs" / "unplaced_along.png")
