"""The monaco sample on its route drawn 10 m north of the road, in headless Chromium. With
the map's bias unlearned and the separation from dead reckoning unwatched
(``extensions.map_bias`` and ``extensions.dr_separation`` off), every route update follows
the wrong map and the run leaves the tunnel 10 m from the returning fixes under a sigma of
well under a metre: the page must say so in its warnings, where a user without ground truth
looks. With the defaults, the same outage's exit is a note, within its sigmas. With
ROUTEFUSE_UPDATE_SCREENSHOT=1 the screenshot replaces docs/exit_check.png."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from _browser import panel_screenshot, route_moved_north, served, session_page, wait_until

from estimator.params import Params, with_values

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 1400, "height": 1100}
TRUSTING = {"extensions.map_bias": False, "extensions.dr_separation": False}


@pytest.fixture
def route_10m_north(tmp_path):
    return route_moved_north(
        REPO / "sample_logs" / "monaco_tunnel.route.geojson",
        0.00009,
        tmp_path / "monaco_10m_north.route.geojson",
    )


def test_an_outage_that_followed_a_wrong_map_is_named_on_the_page(
    browser, tmp_path, route_10m_north
):
    log = REPO / "sample_logs" / "monaco_tunnel.mcap"
    params = with_values(Params(), TRUSTING)
    with served(log, route_10m_north, params=params) as (server, controller, app):
        run = controller.session.proposed
        (x,) = run.exits
        assert x.overconfident and x.distance_m > 8.0 and x.estimate_sigma_m < 1.0
        (line,) = [w for w in run.warnings if "m from the fixes after it" in w]
        page, view = session_page(browser, server, app, VIEWPORT)
        text = page.inner_text("body")
        assert line in text, text[:2000]
        assert "the route updates pulled it off unnoticed" in text
        assert "exit of the outage at 108.4-224.4 s" in text
        # on the map: the line from the estimate to the fixes, red and labelled
        layer = view.layers.layers["exits"]
        beyond = layer._segments["beyond"].points
        assert beyond.shape == (1, 2, 3)
        length = float(np.hypot(*(beyond[0, 0, :2] - beyond[0, 1, :2])))
        assert length == pytest.approx(x.distance_m, abs=1e-3)
        (label,) = layer._labels.values()
        assert label.text == f"exit {x.distance_m:.1f} m, {x.chi2**0.5:.1f} sigma"
        page.get_by_role("tab", name="Layers").click()
        assert "outage exits" in page.inner_text("body")
        # the Plots tab's table (and the Compare tab's, from the same rows) counts them
        page.get_by_role("tab", name="Plots").click()
        row = r"outages ended beyond their sigmas \(exit check\)\s+0\s+1\b"
        wait_until(lambda: re.search(row, page.inner_text("body")), 20, "the exit row")
        page.get_by_role("tab", name="Match").click()
        shot = tmp_path / "exit_check.png"
        view.seek(232.0)
        view._focus = (x.estimate_at - x.error / 2, 60.0)  # the camera over the exit
        view.place_camera()
        panel_screenshot(page, shot)
        page.close()
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(shot, REPO / "docs" / "exit_check.png")


def test_with_the_defaults_the_same_exit_is_a_note(browser, route_10m_north):
    log = REPO / "sample_logs" / "monaco_tunnel.mcap"
    with served(log, route_10m_north) as (server, controller, app):
        run = controller.session.proposed
        (x,) = run.exits
        assert not x.overconfident
        assert not [w for w in run.warnings if "from the fixes after it" in w]
        page, _ = session_page(browser, server, app, VIEWPORT)
        text = page.inner_text("body")
        assert f"were {x.distance_m:.1f} m from the estimate" in text, text[:2000]
        page.close()
