"""A log of two IMU topics opened from the Files tab in headless Chromium: without a topic
chosen for the server, 'open' is refused in a notification that says to restart
``routefuse serve`` with --imu-topic (the browser has no topic control), and the session
before stays; a server started with --imu-topic /imu/raw --no-wheel opens it on that topic,
without its wheel speed."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from _browser import served, session_page, wait_until

from estimator.io import TopicChoice
from tests.inspector.fake_runs import MONACO_LOG, MONACO_ROUTE, two_imu_log

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1400, "height": 1000}


def _pick(page, label: str, option: str) -> None:
    """Open the dropdown labelled ``label`` and click ``option`` in its list."""
    uid = page.locator("label", has_text=re.compile(f"^{re.escape(label)}$")).first
    page.locator(f"[id='{uid.get_attribute('for')}']").click()
    page.get_by_role("option", name=option, exact=True).click()


def _open_two_imu(page) -> None:
    page.get_by_text("Legend").first.click()  # folded: the Files tab in view
    page.get_by_role("tab", name="Files").click()
    _pick(page, "log", "data/two_imu.bag")
    _pick(page, "route file", "data/two_imu.route.geojson")
    page.get_by_role("button", name="open", exact=True).first.click()


def test_a_log_of_two_imu_topics_says_to_restart_serve_with_the_flag(browser, tmp_path):
    data = tmp_path / "data"
    two_imu_log(data)
    log = Path(shutil.copy(MONACO_LOG, data / "monaco.mcap"))
    route = Path(shutil.copy(MONACO_ROUTE, data / "monaco.route.geojson"))
    with served(log, route, data_dirs=[data]) as (server, controller, app):
        first = controller.session
        page, _ = session_page(browser, server, app, VIEWPORT)
        _open_two_imu(page)
        wait_until(lambda: "Kept the previous session" in page.inner_text("body"), 60, "refusal")
        body = page.inner_text("body")
        assert (
            "two_imu.bag: several imu topics: /imu/data, /imu/raw; choose one by restarting "
            "'routefuse serve' with --imu-topic TOPIC"
        ) in body
        assert controller.session is first
        page.wait_for_timeout(1500)  # the notification's slide-in
        page.screenshot(path=str(tmp_path / "topics.png"))
        page.close()


def test_a_server_started_with_imu_topic_opens_the_log_on_it(browser, tmp_path):
    data = tmp_path / "data"
    two_imu_log(data)
    chosen = TopicChoice(imu="/imu/raw", no_wheel=True)
    with served(data_dirs=[data], topics=chosen) as (server, controller, _app):
        page = browser.new_page(viewport=VIEWPORT)
        page.set_default_timeout(90_000)
        page.goto(f"http://127.0.0.1:{server.get_port()}")
        wait_until(lambda: "nothing loaded" in page.inner_text("body"), 60, "the empty page")
        _open_two_imu(page)
        wait_until(
            lambda: controller.session is not None and controller.session.topics == chosen,
            240,
            "a run on /imu/raw",
        )
        assert controller.session.inputs.log.wheel is None
        wait_until(lambda: "match attempts" in page.inner_text("body"), 60, "the session shown")
        page.close()
