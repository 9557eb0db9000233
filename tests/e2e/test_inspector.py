"""The inspector in headless Chromium (Debian's, driven by Playwright): load the long-tunnel
sample with the real estimator, step frames, tune a gate until matches are rejected, jump to a
rejected attempt and read why, and keep a screenshot for the README."""

from __future__ import annotations

import re
import shutil
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "sample_logs" / "long_tunnel.mcap"
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
VIEWPORT = {"width": 1400, "height": 900}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _sample(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The bundled long-tunnel sample (or, before it is bundled, the same scenario simulated)."""
    route = SAMPLE.with_name("long_tunnel.route.geojson")
    if SAMPLE.exists() and route.exists():
        return SAMPLE, route
    from estimator.simulate import simulate

    out = tmp_path_factory.mktemp("sample")
    simulate("long_tunnel", seed=0).write(out)
    return out / "long_tunnel.mcap", out / "long_tunnel.route.geojson"


UPLOAD_LIMIT = 1_000_000


@pytest.fixture(scope="module")
def inspector(tmp_path_factory):
    from inspector.commands.serve import start

    log, route = _sample(tmp_path_factory)
    extra = tmp_path_factory.mktemp("extra")
    (extra / "broken.mcap").write_bytes(b"this is not an mcap file")
    server, controller, app = start(
        host="127.0.0.1",
        port=_free_port(),
        data_dirs=[extra],
        log=log,
        route=route,
        max_upload_bytes=UPLOAD_LIMIT,
    )
    try:
        assert controller.wait_idle(240), "the sample did not load"
        assert controller.session is not None
        yield server, controller, app
    finally:
        app.close()
        controller.close()
        server.stop()


@pytest.fixture(scope="module")
def browser():
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed (apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        yield b
        b.close()


def _wait(predicate, timeout: float = 30.0, what: str = "condition"):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


def _open(browser, inspector, *, settle: bool = True, viewport: dict | None = None):
    server, _, app = inspector
    before = {v.client.client_id for v in app.views()}
    page = browser.new_page(viewport=viewport or VIEWPORT)
    page.set_default_timeout(90_000)  # software WebGL on a busy machine: slow, not stuck
    page.goto(f"http://127.0.0.1:{server.get_port()}")
    _wait(lambda: "Connecting" not in page.inner_text("body"), 40, "the page to connect")
    _wait(lambda: "match attempts" in page.inner_text("body"), 40, "the session")
    view = _wait(
        lambda: [v for v in app.views() if v.client.client_id not in before], 10, "the tab's view"
    )[0]
    if settle:
        _settle(page)
    return page, view


FRAME_RATE_JS = """() => new Promise(done => {
    let n = 0; const t0 = performance.now();
    const f = () => { n++; if (performance.now() - t0 < 500) requestAnimationFrame(f);
                      else done(n / 0.5); };
    requestAnimationFrame(f);
})"""


def _settle(page, timeout: float = 90.0) -> None:
    """Wait until the page renders at a few frames per second: software WebGL compiles its
    shaders after the first scene arrives, and clicks wait for a stable frame until then."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if page.evaluate(FRAME_RATE_JS) >= 5:
            return
    raise AssertionError("the page never settled")


@pytest.fixture(scope="module")
def page(browser, inspector) -> Iterator:
    pg, view = _open(browser, inspector)
    yield pg, view
    pg.close()


def _frame(page) -> int:
    m = re.search(r"frame (\d+) / (\d+)", page.inner_text("body"))
    assert m, "no frame label"
    return int(m.group(1))


def _click(page, name: str) -> None:
    page.get_by_role("button", name=name, exact=True).first.click()


def _canvas(page) -> bytes:
    return page.locator("canvas[data-engine^='three.js']").first.screenshot()


def test_step_frames_with_buttons_and_keys(page):
    pg, view = page
    _click(pg, "10 »")
    f0 = _wait(lambda: _frame(pg) > 1 and _frame(pg), what="first step")
    pose = view.layers.layers["proposed"]._handles["pose"]
    p0 = np.array(pose.position)
    _click(pg, "next ›")
    _wait(lambda: _frame(pg) == f0 + 1, what="next frame")
    _click(pg, "‹ prev")
    _wait(lambda: _frame(pg) == f0, what="previous frame")
    pg.mouse.click(200, 700)  # focus the page (not an input) so hotkeys reach viser
    pg.keyboard.press("ArrowRight")
    pg.keyboard.press("ArrowRight")
    _wait(lambda: _frame(pg) == f0 + 2, what="keyboard steps")
    assert np.linalg.norm(np.array(pose.position) - p0) > 0.1  # the vehicle node moved

    # Following the vehicle, a ten-frame step changes what the browser renders.
    pg.get_by_role("checkbox").first.check()  # "follow vehicle" is the first checkbox
    time.sleep(1.5)
    before = _canvas(pg)
    _click(pg, "10 »")
    _wait(lambda: _frame(pg) == f0 + 12, what="ten frames")
    _wait(lambda: _canvas(pg) != before, 10, "the rendered scene to change")


def test_play_and_pause(page):
    pg, view = page
    f0 = _frame(pg)
    _click(pg, "play")
    _wait(lambda: _frame(pg) > f0 + 20, 20, "playback to advance")
    _click(pg, "pause")
    _wait(lambda: not view.playhead.playing, 5, "the pause")
    f1 = _frame(pg)
    time.sleep(1.0)
    assert _frame(pg) == f1


def test_parameter_slider_reruns_and_changes_metrics(page, inspector):
    pg, _ = page
    _, controller, _ = inspector
    pg.get_by_role("tab", name="Plots").click()
    table = _wait(
        lambda: re.search(r"position deviation RMSE.*", pg.inner_text("body")),
        10,
        "the metrics table",
    ).group(0)
    attempts = re.search(r"match attempts \(accepted / rejected\).*", pg.inner_text("body"))
    pg.get_by_role("tab", name="Parameters").click()
    uid = pg.locator("label", has_text=re.compile(r"^min_pairs$")).first.get_attribute("for")
    thumb = pg.locator(f"[id='{uid}'] [role='slider']")
    thumb.focus()
    thumb.press("End")  # 500 pairs: more than any window has, so every attempt is rejected
    _wait(lambda: controller.params.gates.min_pairs == 500, 10, "the parameter to arrive")
    assert controller.wait_idle(120)
    pg.get_by_role("tab", name="Plots").click()

    def changed():
        text = pg.inner_text("body")
        m = re.search(r"match attempts \(accepted / rejected\).*", text)
        return m and m.group(0) != attempts.group(0) and "(0 / " in m.group(0)

    _wait(changed, 30, "the metrics to change")
    new_table = re.search(r"position deviation RMSE.*", pg.inner_text("body")).group(0)
    assert new_table != table


def test_next_rejected_attempt_shows_the_failed_gate(page, inspector):
    pg, view = page
    _, controller, _ = inspector
    assert controller.session.params.gates.min_pairs == 500
    pg.get_by_role("tab", name="Match").click()
    start = _frame(pg)
    _click(pg, "rejected ›")
    _wait(lambda: "REJECTED" in pg.inner_text("body"), 10, "a rejected attempt")
    text = pg.inner_text("body")
    assert re.search(r"min_pairs\s+[\d.]+\s+>= 500\.000\s+✗ FAILED", text), text[:2000]
    assert _frame(pg) > start
    i = view.session.timeline.match_at(view.playhead.t)
    assert i is not None and not view.session.proposed.matches[i].accepted
    assert view.layers.layers["match"]._handles["label"].text.endswith("rejected: min_pairs")


def test_screenshot_for_the_readme(page):
    pg, _ = page
    close = pg.locator(".mantine-Notification-closeButton")
    for i in range(close.count()):
        close.nth(i).dispatch_event("click")  # the "software WebGL" notice covers the map
    time.sleep(1.5)
    out = REPO / "docs" / "inspector.png"
    out.parent.mkdir(exist_ok=True)
    tmp = out.with_suffix(".tmp.png")
    pg.screenshot(path=str(tmp))
    import matplotlib.image as mpimg

    img = mpimg.imread(str(tmp))[..., :3]
    scene = img[:, : int(img.shape[1] * 0.6)]  # left of the control panel
    background = np.median(scene.reshape(-1, 3), axis=0)
    drawn = np.any(np.abs(scene - background) > 0.1, axis=2)
    assert drawn.mean() > 0.002, "the 3D view is blank"
    colours = {tuple(c) for c in np.round(scene[drawn] * 4).astype(int)}
    assert len(colours) >= 4, "the 3D view shows fewer layers than expected"
    shutil.move(tmp, out)


def test_two_tabs_keep_their_own_time(browser, inspector, page):
    pg1, _ = page
    f1 = _frame(pg1)
    pg2, _ = _open(browser, inspector, settle=False, viewport={"width": 900, "height": 600})
    try:
        for _ in range(2):  # dispatched: this tab need not finish compiling its shaders first
            pg2.get_by_role("button", name="10 »", exact=True).dispatch_event("click")
        _wait(lambda: _frame(pg2) != f1, what="the second tab to step")
        time.sleep(0.5)
        assert _frame(pg1) == f1
    finally:
        pg2.close()


def _notified(page, text: str) -> bool:
    return text in page.inner_text("body")


def test_a_failing_open_from_the_picker_keeps_the_session(page, inspector):
    pg, view = page
    _, controller, _ = inspector
    before = controller.session
    pg.get_by_role("tab", name="Files").click()
    uid = pg.locator("label", has_text=re.compile(r"^log$")).first.get_attribute("for")
    pg.locator(f"[id='{uid}']").click()
    pg.get_by_role("option", name="extra0/broken.mcap").click()
    _wait(lambda: view.log_choice.value == "extra0/broken.mcap", 10, "the pick to arrive")
    _click(pg, "open")
    _wait(lambda: _notified(pg, "Kept the previous session"), 30, "the notification")
    assert "broken.mcap" in pg.inner_text("body")
    assert controller.wait_idle(30) and controller.session is before
    _click(pg, "next ›")  # still usable
    _wait(lambda: "frame" in pg.inner_text("body"), 5, "the frame label")


def test_save_parameters_downloads_toml_that_loads_back(page, inspector, tmp_path):
    from estimator.params import load_params

    pg, _ = page
    _, controller, _ = inspector
    pg.get_by_role("tab", name="Parameters").click()
    with pg.expect_download(timeout=20_000) as info:
        _click(pg, "save parameters")
    path = tmp_path / info.value.suggested_filename
    info.value.save_as(path)
    assert path.name.endswith(".toml")
    assert load_params(path) == controller.params
    assert controller.params.gates.min_pairs == 500


def test_upload_a_route_and_refuse_an_oversized_file(page, inspector, tmp_path):
    pg, view = page
    _, controller, _ = inspector
    pg.get_by_role("tab", name="Files").click()
    route = tmp_path / "my_route.geojson"
    route.write_bytes(controller.session.route_path.read_bytes())
    with pg.expect_file_chooser() as chooser:
        _click(pg, "upload route")
    chooser.value.set_files(str(route))
    _wait(lambda: _notified(pg, "press 'open' to load it"), 30, "the upload")
    assert any(n.endswith("my_route.geojson") for n in view.route_choice.options)
    uploaded = [p for p in controller.uploads.path.iterdir() if p.name.endswith("my_route.geojson")]
    assert len(uploaded) == 1 and uploaded[0].read_bytes() == route.read_bytes()

    big = tmp_path / "big.mcap"
    big.write_bytes(b"\0" * (UPLOAD_LIMIT + 1))
    with pg.expect_file_chooser() as chooser:
        _click(pg, "upload log")
    chooser.value.set_files(str(big))
    _wait(lambda: _notified(pg, "exceeds the limit"), 30, "the refusal")
    assert not any(p.name.endswith("big.mcap") for p in controller.uploads.path.iterdir())
