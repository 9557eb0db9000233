"""A log whose GNSS is stamped 18 s late (GPS time against UTC), in headless Chromium: the
check at load names the offset and the setting that removes it where the user looks (the
status line's warnings). That the line goes once the setting is made is the run's
(tests/estimator/io/test_plausibility_configured_clocks.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from _browser import panel_screenshot, served, session_page

from estimator.io import load_log, write_bag

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 1400, "height": 1100}


def _gnss_late(tmp_path: Path) -> Path:
    log = load_log(REPO / "sample_logs" / "monaco_tunnel.mcap")
    path = tmp_path / "gps_time.mcap"
    write_bag(
        path,
        imu=log.imu,
        gnss=log.gnss,
        wheel=log.wheel,
        truth=log.truth,
        header_stamps={"gnss": log.gnss.t + 18.0},
    )
    return path


def test_a_gnss_clock_18_s_late_is_named_on_the_page_with_its_setting(browser, tmp_path):
    route = REPO / "sample_logs" / "monaco_tunnel.route.geojson"
    with served(_gnss_late(tmp_path), route) as (server, _, app):
        page, _view = session_page(browser, server, app, VIEWPORT)
        text = page.inner_text("body")
        assert "gps_time.mcap: IMU /imu/data: its stamps look 18.0" in text
        assert "18 s is GPS time against UTC): set sensors.gnss_time_offset_s = -18.0" in text
        panel_screenshot(page, tmp_path / "gnss_late.png")
        page.close()
