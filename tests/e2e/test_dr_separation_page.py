"""Corpus drive 5 (``routefuse simulate --stress 5``) in headless Chromium: its spiral tunnel
trips the dead-reckoning separation gate, and the page must say so where a user looks: the
status line's warning, the Match tab of the attempt that undid the route updates, and the
note on the outage's later attempts. With ROUTEFUSE_UPDATE_SCREENSHOT=1 the screenshot of the
undone attempt replaces docs/dr_separation.png."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest
from _browser import panel_screenshot, served, session_page, wait_until

from estimator.results import Gate
from inspector.app.match import UNDONE_HERE
from inspector.cli.main import main
from tests._session11_fit import undoing_params

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 1400, "height": 1250}


def _dr_separation(m):
    return next((g for g in m.gates if g.gate is Gate.DR_SEPARATION and not g.passed), None)


def _attempt(page) -> int:
    m = re.search(r"Attempt #(\d+) \(", page.inner_text("body"))
    return int(m.group(1)) if m else -1


def test_undone_route_updates_on_the_page(browser, tmp_path):
    assert main(["simulate", "--stress", "5", "--out", str(tmp_path)]) == 0
    bag, route = tmp_path / "stress_5.mcap", tmp_path / "stress_5.route.geojson"
    with served(bag, route, params=undoing_params()) as (server, controller, app):
        matches = controller.session.proposed.matches
        failed = [(i, _dr_separation(m)) for i, m in enumerate(matches) if _dr_separation(m)]
        undone = [i for i, g in failed if "none taken since" not in g.note]
        later = [i for i, g in failed if "none taken since" in g.note]
        assert len(undone) == 1 and later and min(later) > undone[0], failed[:3]
        u = undone[0]
        at_s = float(controller.session.timeline.match_t[u])

        page, view = session_page(browser, server, app, VIEWPORT)
        status = page.inner_text("body")
        assert f"route updates undone at {at_s:.1f} s" in status, status[:1500]
        assert "warning about this log and its run" in status

        page.get_by_role("tab", name="Match").click()
        view.seek(0.0)
        wait_until(lambda: "No match attempt before this time" in page.inner_text("body"), 20)
        rejected = page.get_by_role("button", name="rejected ›", exact=True)
        for _ in range(u + 1):  # the refused attempts before it, if any, then it
            if _attempt(page) >= u:
                break
            shown = _attempt(page)
            rejected.click()
            wait_until(lambda shown=shown: _attempt(page) > shown, 20, "the next refused attempt")
        assert _attempt(page) == u
        text = page.inner_text("body")
        assert re.search(r"dr_separation\s+[\d.]+\s+<= 13\.800\s+✗ FAILED", text), text[:3000]
        assert "REJECTED by dr_separation" in text and UNDONE_HERE in text
        assert (
            view.layers.layers["match"]._handles["label"].text.endswith("rejected: dr_separation")
        )
        shot = tmp_path / "dr_separation.png"
        panel_screenshot(page, shot)

        rejected.click()
        wait_until(lambda: _attempt(page) > u, 20, "a later attempt")
        assert _attempt(page) in later
        text = page.inner_text("body")
        note = f"the outage's route updates were undone at {at_s:.1f} s: none taken since"
        assert note in text and "REJECTED by" in text and UNDONE_HERE not in text
        page.close()
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(shot, REPO / "docs" / "dr_separation.png")
