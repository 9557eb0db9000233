"""Corpus drive 32 (``routefuse simulate --stress 32``: long tunnel, no odometer) in headless
Chromium: every route update of its outage is accepted and the trace sits on the route, while
the filter does not know within 100 m where along the road it is. The status line's warnings
must say so, whole, and the Plots tab must draw the run's own sigma beside its error against
truth. With ROUTEFUSE_UPDATE_SCREENSHOT=1 the screenshots replace docs/unplaced_along.png and
docs/plots_sigma.png."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pytest
from _browser import panel_screenshot, served, session_page, wait_until

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
        page.get_by_role("tab", name="Plots").click()
        wait_until(lambda: "proposed 1-sigma" in page.inner_text("body"), 30, "the sigma series")
        plots = tmp_path / "plots_sigma.png"
        page.get_by_text("horizontal error against ground truth").scroll_into_view_if_needed()
        time.sleep(1.0)
        page.screenshot(path=str(plots))
        page.close()
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(shot, REPO / "docs" / "unplaced_along.png")
        shutil.move(plots, REPO / "docs" / "plots_sigma.png")
