"""The monaco sample on its route drawn the other way, in headless Chromium: every match in the
tunnel is refused for its heading and routefuse is dead reckoning there, which the page must say
where the user looks (the status line's warnings), with the gates that refused them; and the
same route out and back along the road is matched as the route itself."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from _browser import panel_screenshot, served, session_page

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 1400, "height": 1100}


def _route(tmp_path: Path, name: str, legs: str) -> Path:
    drawn = json.loads((REPO / "sample_logs" / "monaco_tunnel.route.geojson").read_text())
    coords = drawn["features"][0]["geometry"]["coordinates"]
    line = {"reversed": coords[::-1], "out_and_back": coords + coords[::-1][1:]}[legs]
    path = tmp_path / name
    path.write_text(json.dumps({"type": "LineString", "coordinates": line}))
    return path


def test_a_route_drawn_the_other_way_is_named_on_the_page(browser, tmp_path):
    log = REPO / "sample_logs" / "monaco_tunnel.mcap"
    with served(log, _route(tmp_path, "reversed.geojson", "reversed")) as (server, _, app):
        page, _view = session_page(browser, server, app, VIEWPORT)
        text = page.inner_text("body")
        assert "proposed run: all 112 match attempts in the outage at 108.4-224.4 s were " in text
        assert "refused (heading 106, min_pairs 6): it was dead-reckoned there" in text
        panel_screenshot(page, tmp_path / "refused_outage.png")
        page.close()


def test_the_road_out_and_back_is_matched_and_says_nothing_of_refusals(browser, tmp_path):
    log = REPO / "sample_logs" / "monaco_tunnel.mcap"
    route = _route(tmp_path, "out_and_back.geojson", "out_and_back")
    with served(log, route) as (server, controller, app):
        run = controller.session.proposed
        assert sum(m.accepted for m in run.matches) == 112
        page, _view = session_page(browser, server, app, VIEWPORT)
        assert "were refused" not in page.inner_text("body")
        page.close()
