"""The inspector on the real logs of ../shared/data (Debian chromium through Playwright), each
opened as ``routefuse serve LOG --route ROUTE --config sample_logs/configs/...`` would: the
comma2k19 I-280 car with its route and truth, and the Husky ROS 1 bag (rotated IMU, no tf) with
a route derived from its own GNSS into tmp_path. A screenshot of each must show a drawn scene,
the frame label and the metrics."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import numpy as np
import pytest
from _browser import free_port
from _browser import wait_until as _wait

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data"
CONFIGS = REPO / "sample_logs" / "configs"
VIEWPORT = {"width": 1400, "height": 900}
LOGS = {
    "comma2k19": (DATA / "comma2k19" / "i280.mcap", CONFIGS / "comma2k19_i280.toml"),
    "husky": (DATA / "robot_localization" / "test1.bag", CONFIGS / "husky_test1.toml"),
}


FRAME_RATE_JS = """() => new Promise(done => {
    let n = 0; const t0 = performance.now();
    const f = () => { n++; if (performance.now() - t0 < 500) requestAnimationFrame(f);
                      else done(n / 0.5); };
    requestAnimationFrame(f);
})"""


def _route_for(name: str, log_path: Path, tmp_path: Path) -> Path:
    if name == "comma2k19":
        return DATA / "comma2k19" / "i280_route.geojson"
    from estimator.io import load_log
    from estimator.io.routebuild import route_from_gnss

    route = tmp_path / "husky_test1.route.geojson"
    gj = route_from_gnss(load_log(log_path), name="Husky lot (from its own GNSS)")
    route.write_text(json.dumps(gj), encoding="utf-8")
    return route


@pytest.mark.parametrize("name", list(LOGS))
def test_inspector_shows_the_real_log(name, browser, tmp_path):
    log_path, config = LOGS[name]
    if not log_path.exists():
        pytest.skip(f"real data not found: {log_path}")
    from estimator.params import load_params
    from inspector.cli.serve import start

    route = _route_for(name, log_path, tmp_path)
    params = load_params(config)
    server, controller, app = start(
        host="127.0.0.1", port=free_port(), data_dirs=[], log=log_path, route=route, params=params
    )
    page = None
    try:
        assert controller.wait_idle(240), f"{name} did not load"
        session = controller.session
        assert session is not None, "no session"
        assert session.params == params  # the config reached the estimator
        att = np.degrees(session.proposed.epochs.attitude)
        # level (a wrong IMU rotation shows as tens of degrees of roll or pitch)
        assert np.percentile(np.abs(att[:, :2]), 95) < 5.0
        # the estimate follows the route (GNSS is never missing: no outage is injected)
        foot = session.inputs.route.project(session.proposed.epochs.position[:, :2])
        assert np.percentile(foot.distance, 95) < 6.0
        if name == "comma2k19":
            assert session.scene.truth is not None

        page = browser.new_page(viewport=VIEWPORT)
        page.goto(f"http://127.0.0.1:{server.get_port()}")
        _wait(lambda: "Connecting" not in page.inner_text("body"), 40, "the page to connect")
        _wait(lambda: "match attempts" in page.inner_text("body"), 40, "the session")
        _wait(lambda: page.evaluate(FRAME_RATE_JS) >= 5, 90, "the page to settle")
        text = page.inner_text("body")
        assert log_path.name in text
        frame = re.search(r"frame (\d+) / (\d+)", text)
        assert frame, "no frame label"
        assert int(frame.group(2)) == session.timeline.n_frames
        page.get_by_role("tab", name="Plots").click()
        _wait(lambda: "position deviation RMSE" in page.inner_text("body"), 10, "the metrics table")
        close = page.locator(".mantine-Notification-closeButton")
        for i in range(close.count()):
            close.nth(i).dispatch_event("click")  # the "software WebGL" notice
        time.sleep(1.5)
        shot = tmp_path / f"{name}.png"
        page.screenshot(path=str(shot))
        import matplotlib.image as mpimg

        img = mpimg.imread(str(shot))[..., :3]
        scene = img[:, : int(img.shape[1] * 0.6)]  # left of the control panel
        background = np.median(scene.reshape(-1, 3), axis=0)
        drawn = np.any(np.abs(scene - background) > 0.1, axis=2)
        assert drawn.mean() > 0.002, f"{name}: the 3D view is blank"
        colours = {tuple(c) for c in np.round(scene[drawn] * 4).astype(int)}
        assert len(colours) >= 3, f"{name}: the 3D view shows fewer layers than expected"
    finally:
        if page is not None:
            page.close()
        app.close()
        controller.close()
        server.stop()
