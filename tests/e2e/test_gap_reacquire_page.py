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
from pathlib import Path

import pytest
from _browser import panel_screenshot, served, session_page, wait_until

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

        page, view = session_page(browser, server, app, VIEWPORT)
        status = page.inner_text("body")
        assert f"heading re-acquired from the route at {t_match:.1f} s" in status, status[:1500]

        page.get_by_role("tab", name="Match").click()
        view.seek(t_match + 0.01)
        wait_until(lambda: f"Attempt #{i} of" in page.inner_text("body"), 20, "the attempt")
        text = page.inner_text("body")
        assert "ACCEPTED (re-anchored)" in text, text[:3000]
        assert re.search(r"rotation\s+[\d.]+\s+<= 15\.000\s+✗ FAILED", text), text[:3000]
        assert "the IMU gap that ended at" in text and "deg here)" in text
        shot = tmp_path / "gap_reacquire.png"
        panel_screenshot(page, shot)
        page.close()
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(shot, REPO / "docs" / "gap_reacquire.png")
