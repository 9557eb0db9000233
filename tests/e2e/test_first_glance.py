"""What a person sees first (issue 19): a legend on the map's side without opening a tab, one
next to each layer's toggle, and the page opening at the first refused match attempt, zoomed
to it, with the Match tab filled. Clicks and reads the page as a person does, in Chromium."""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

import pytest
from _browser import served
from _browser import wait_until as _wait

from estimator.params import Params, with_values
from inspector.layers import LAYER_TYPES, legend_entries

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "monaco_tunnel.mcap"
ROUTE = REPO / "sample_logs" / "monaco_tunnel.route.geojson"
# a tight residual gate: some of the tunnel's attempts are refused, so there is a story
TIGHT = with_values(Params(), {"gates.max_residual_m": 0.6})


@pytest.fixture(scope="module")
def session():
    with served(LOG, ROUTE, params=TIGHT) as running:
        yield running


def test_the_page_opens_at_the_first_refusal_with_a_legend(browser, session, tmp_path):
    server, controller, app = session
    session = controller.session
    tl = session.timeline
    first_refused = tl.next_match(-1e9, rejected_only=True)
    assert first_refused is not None, "the tight gate refused nothing: no story to open at"
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.set_default_timeout(90_000)
    try:
        page.goto(f"http://127.0.0.1:{server.get_port()}")
        _wait(lambda: "match attempts" in page.inner_text("body"), what="the session")
        _wait(lambda: "REJECTED" in page.inner_text("body"), 60, "the refused attempt")
        body = page.inner_text("body")
        # the compact legend, visible without opening a tab: every colour's meaning
        for _, meaning in legend_entries():
            assert meaning in body, meaning
        # opened at the first refused attempt, the Match tab filled with its gates
        view = app.views()[-1]
        assert view.playhead.t == pytest.approx(float(tl.match_t[first_refused]))
        assert "No match attempt before this time" not in body
        assert re.search(r"✗ FAILED", body), body[:1500]
        # zoomed to it, not over the whole drive
        cam = view.client.camera
        _wait(lambda: cam.update_timestamp > 0, 20, "the browser's camera")
        assert float(cam.position[2]) < 0.5 * session.scene.extent_m
        page.screenshot(path=str(tmp_path / "first_glance.png"))
        # the Layers tab: each toggle with its colours
        page.get_by_role("tab", name="Layers").click()
        for cls in LAYER_TYPES:
            page.get_by_text(cls.label, exact=True).first.wait_for()
        page.screenshot(path=str(tmp_path / "layers_tab.png"))
    finally:
        page.close()


def test_top_down_view_shows_the_whole_drive_after_the_opening_zoom(browser, session, tmp_path):
    """The page opens zoomed to its first refused attempt; **top-down view** then shows the
    whole drive. It went back to the opening zoom instead (the button did nothing visible)."""
    server, controller, app = session
    extent = controller.session.scene.extent_m
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.set_default_timeout(90_000)
    try:
        page.goto(f"http://127.0.0.1:{server.get_port()}")
        _wait(lambda: "REJECTED" in page.inner_text("body"), 60, "the refused attempt")
        cam = app.views()[-1].client.camera
        _wait(lambda: cam.update_timestamp > 0, 20, "the browser's camera")
        _wait(lambda: float(cam.position[2]) < 0.5 * extent, 20, "the opening zoom")
        page.get_by_role("button", name="top-down view", exact=True).click()
        _wait(
            lambda: float(cam.position[2]) >= 0.6 * extent,
            20,
            lambda: (
                f"the whole drive (camera {float(cam.position[2]):.0f} m up, drive {extent:.0f} m)"
            ),
        )
        # and all of it: the monaco drive runs north-south, across the window's height
        up = float(cam.position[2]) * math.tan(float(cam.fov) / 2)
        assert up >= 0.5 * extent, (up, extent)
        page.screenshot(path=str(tmp_path / "top_down.png"))
    finally:
        page.close()


def test_another_log_opened_from_the_files_tab_opens_at_its_own_story(browser, session, tmp_path):
    """A log opened from the Files tab opens as the first did: at its first refused attempt
    (else its first), the camera on it. The camera stayed where the previous drive was, and the
    map was blank until **top-down view** was pressed."""
    server, controller, app = session
    first = controller.session
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.set_default_timeout(90_000)
    try:
        page.goto(f"http://127.0.0.1:{server.get_port()}")
        _wait(lambda: "REJECTED" in page.inner_text("body"), 60, "the refused attempt")
        view = app.views()[-1]
        cam = view.client.camera
        _wait(lambda: cam.update_timestamp > 0, 20, "the browser's camera")
        page.get_by_role("tab", name="Files").click()
        uid = page.locator("label", has_text=re.compile(r"^log$")).first.get_attribute("for")
        page.locator(f"[id='{uid}']").click()
        page.get_by_role("option", name="sample_logs/spiral_tunnel.mcap").click()
        _wait(lambda: view.files.route_choice.value.endswith("spiral_tunnel.route.geojson"))
        page.get_by_role("button", name="open", exact=True).click()
        _wait(lambda: view.session is not None and view.session is not first, 240, "the new log")
        s = view.session
        tl = s.timeline
        i = tl.next_match(-1e9, rejected_only=True)
        i = tl.next_match(-1e9) if i is None else i
        assert i is not None
        _wait(lambda: view.playhead.t == pytest.approx(float(tl.match_t[i])), 20, "its story")
        xy = s.scene.match_xy[i]

        def on_it():
            look = cam.look_at
            height = float(cam.position[2])
            return height < 0.5 * s.scene.extent_m and math.dist(look[:2], xy) < height

        _wait(on_it, 20, lambda: f"the camera on attempt #{i} (looks at {cam.look_at})")
        time.sleep(2.0)
        page.screenshot(path=str(tmp_path / "another_log.png"))
    finally:
        page.close()
        controller.open(first.log_path, first.route_path)
        assert controller.wait_idle(240)
