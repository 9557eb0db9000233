"""The inspector in headless Chromium (Debian's, driven by Playwright): load the long-tunnel
sample with the real estimator, step frames, tune a gate until matches are rejected, jump to a
rejected attempt and read why, and keep a screenshot for the README."""

from __future__ import annotations

import os
import re
import shutil
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from _browser import free_port
from _browser import wait_until as _wait

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "sample_logs" / "long_tunnel.mcap"
VIEWPORT = {"width": 1400, "height": 900}


def _sample(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The bundled long-tunnel sample (or, before it is bundled, the same scenario simulated)."""
    route = SAMPLE.with_name("long_tunnel.route.geojson")
    if SAMPLE.exists() and route.exists():
        return SAMPLE, route
    from estimator.sim import simulate

    out = tmp_path_factory.mktemp("sample")
    simulate("long_tunnel", seed=0).write(out)
    return out / "long_tunnel.mcap", out / "long_tunnel.route.geojson"


UPLOAD_LIMIT = 1_000_000
HOSTILE_NAME = '<img src=x onerror="window.pwned=1">[link](javascript:window.pwned=2)*bold*'
"""a data folder's name that runs script if the page renders it as HTML or markdown"""


@pytest.fixture(scope="module")
def inspector(tmp_path_factory):
    from inspector.cli.serve import start

    log, route = _sample(tmp_path_factory)
    extra = tmp_path_factory.mktemp("extra")
    (extra / "broken.mcap").write_bytes(b"this is not an mcap file")
    hostile = tmp_path_factory.mktemp("data") / HOSTILE_NAME
    hostile.mkdir()
    server, controller, app = start(
        host="127.0.0.1",
        port=free_port(),
        data_dirs=[extra, hostile],
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
    start = _frame(pg)  # the page opens where the story is, not at frame 1
    _click(pg, "10 »")
    f0 = _wait(lambda: _frame(pg) == start + 10 and _frame(pg), what="first step")
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
    # the label may still be catching up with the last frames played: wait for the paused one
    f1 = view.session.timeline.frame_at(view.playhead.t) + 1
    _wait(lambda: _frame(pg) == f1, 5, f"the page to show the paused frame {f1}")
    time.sleep(1.0)
    assert _frame(pg) == f1


def _showcase_attempt(session) -> int:
    """An accepted attempt inside the tunnel, on a standard-length window, whose DR window is
    visibly off the route before the fit (the largest innovation of those)."""
    best, best_nu = None, -1.0
    for i, m in enumerate(session.proposed.matches):
        if not m.accepted or not session.proposed.epochs.degraded[m.epoch]:
            continue
        if m.window_length_m > 300.0 or m.n_pairs < 20:
            continue
        nu = float(np.hypot(*m.innovation))
        if nu > best_nu:
            best, best_nu = i, nu
    assert best is not None, "no accepted attempt in the tunnel"
    return best


def test_screenshot_for_the_readme(page, inspector, tmp_path):
    """The natural long_tunnel session (default parameters), stepped into the tunnel to an
    accepted attempt: the DR window, the aligned window, the route segment and the pairs on
    the map, the Match tab open. With ROUTEFUSE_UPDATE_SCREENSHOT=1 the checked screenshot
    replaces docs/inspector.png; otherwise the checkout is left as it was."""
    from estimator.params import Params

    pg, view = page
    _, controller, _ = inspector
    assert controller.session.params == Params()
    i = _showcase_attempt(controller.session)
    tl = controller.session.timeline
    pg.get_by_role("tab", name="Match").click()
    pg.get_by_role("checkbox").first.check()  # follow vehicle
    view.seek(float(tl.match_t[i]) - 0.5 * float(tl.match_t[i] - tl.match_t[i - 1]))
    _click(pg, "attempt ›")
    _wait(lambda: f"Attempt #{i} (" in pg.inner_text("body"), 20, "the attempt")
    text = pg.inner_text("body")
    assert "ACCEPTED" in text and "GNSS missing" in text
    overlay = view.layers.layers["match"]._handles
    assert "accepted" in overlay["label"].text
    # Close over the window (not the vehicle at its end), low enough that the few metres
    # between the DR window and the aligned one show.
    pg.get_by_role("checkbox").first.uncheck()
    _wait(lambda: not view.follow, 10, "follow off")
    m = controller.session.proposed.matches[i]
    height = 110.0
    with view._lock:
        mid = np.mean(np.vstack([m.window_dr, m.route_points]), axis=0)
        mid = 0.4 * mid + 0.6 * np.asarray(m.p_dr)  # the vehicle (the window's end) in view
        c = mid + view._panel_shift(height)[:2]
        cam = view.client.camera
        cam.position = (float(c[0]), float(c[1]) - 0.001 * height, height)
        cam.look_at = (float(c[0]), float(c[1]), 0.0)
    close = pg.locator(".mantine-Notification-closeButton")
    for k in range(close.count()):
        close.nth(k).dispatch_event("click")  # the "software WebGL" notice covers the map
    time.sleep(2.0)
    tmp = tmp_path / "inspector.png"
    pg.screenshot(path=str(tmp))
    import matplotlib.image as mpimg

    img = mpimg.imread(str(tmp))[..., :3]
    scene = img[:, : int(img.shape[1] * 0.6)]  # left of the control panel
    background = np.median(scene.reshape(-1, 3), axis=0)
    drawn = np.any(np.abs(scene - background) > 0.1, axis=2)
    assert drawn.mean() > 0.002, "the 3D view is blank"
    colours = {tuple(c) for c in np.round(scene[drawn] * 4).astype(int)}
    assert len(colours) >= 4, "the 3D view shows fewer layers than expected"
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(tmp, REPO / "docs" / "inspector.png")


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
    _wait(lambda: _frame(pg) > start, 10, "the jump")
    _wait(lambda: "REJECTED" in pg.inner_text("body"), 10, "a rejected attempt")
    text = pg.inner_text("body")
    assert re.search(r"min_pairs\s+\d+\s+>= 500\s+✗ FAILED", text), text[:2000]
    i = view.session.timeline.match_at(view.playhead.t)
    assert i is not None and not view.session.proposed.matches[i].accepted
    assert view.layers.layers["match"]._handles["label"].text.endswith("rejected: min_pairs")


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


def _status(page) -> str:
    """The status line's attempt count ('' while a run's progress replaces it)."""
    m = re.search(r"\d+ match attempts \(\d+ rejected\)", page.inner_text("body"))
    return m.group(0) if m else ""


def test_four_pages_keep_their_time_and_share_a_parameter_change(browser, inspector, page):
    """Four pages on one server, each at its own frame; 'reset to defaults' on one re-runs once
    and every page shows the new run without losing its time."""
    pg1, view1 = page
    _, controller, _ = inspector
    assert controller.params.gates.min_pairs == 500  # left by the tests above
    server, _, app = inspector
    known = {v.client.client_id for v in app.views()}
    new_pages = []
    for _ in range(3):  # opened together: each page's first load overlaps the others'
        pg = browser.new_page(viewport={"width": 800, "height": 560})
        pg.set_default_timeout(90_000)
        pg.goto(f"http://127.0.0.1:{server.get_port()}", wait_until="commit")
        new_pages.append(pg)
    for pg in new_pages:
        _wait(lambda pg=pg: "match attempts" in pg.inner_text("body"), 90, "a page to load")
    new_views = _wait(
        lambda: (
            (v := [v for v in app.views() if v.client.client_id not in known]) and len(v) == 3 and v
        ),
        10,
        "the pages' views",
    )
    others = list(zip(new_pages, [None] * 3, strict=True))
    pages = [(pg1, view1), *others]
    starts = [_frame(pg) for pg in new_pages]  # each opens at the first refused attempt
    sessions: list = []
    unsubscribe = controller.subscribe(on_session=sessions.append)
    try:
        _click(pg1, "next ›")
        # Dispatched (these pages need not finish compiling shaders), in rounds across the
        # pages: viser's panel sends at most one update per 50 ms and keeps only the latest of a
        # burst, so a page's own clicks are spaced the way a person's are.
        for round_ in range(len(others)):
            for k, (pg, _) in enumerate(others, start=1):
                if round_ < k:
                    pg.get_by_role("button", name="10 »", exact=True).dispatch_event("click")
            time.sleep(0.15)
        for k, (pg, _) in enumerate(others, start=1):
            goal = starts[k - 1] + 10 * k
            _wait(
                lambda pg=pg, goal=goal: _frame(pg) == goal,
                30,
                lambda pg=pg, k=k, goal=goal: (
                    f"page {k + 1} to reach frame {goal} (at {_frame(pg)})"
                ),
            )
        frames = [_frame(pg) for pg, _ in pages]
        assert len(set(frames)) == 4, frames
        views = [view1, *new_views]
        assert {v.session.timeline.frame_at(v.playhead.t) + 1 for v in views} == set(frames)
        before = [_status(pg) for pg, _ in pages]
        assert all(before), before

        pg2 = others[0][0]
        pg2.get_by_role("tab", name="Parameters").click()
        pg2.get_by_role("button", name="reset to defaults", exact=True).dispatch_event("click")
        _wait(lambda: controller.params.gates.min_pairs != 500, 10, "the reset to arrive")
        assert controller.wait_idle(120)
        new = controller.session
        assert new.params.gates.min_pairs != 500
        for (pg, _), old in zip(pages, before, strict=True):
            _wait(
                lambda pg=pg, old=old: _status(pg) not in ("", old),
                30,
                "every page to show the re-run",
            )
        expected = f"({int((~new.timeline.match_accepted).sum())} rejected)"
        time.sleep(1.0)
        assert len(sessions) == 1, "one parameter change, one re-run"
        for (pg, _), f in zip(pages, frames, strict=True):
            assert _status(pg).endswith(expected)
            assert _frame(pg) == f  # each page kept its own time
        assert all(v.session is new for v in views)
    finally:
        unsubscribe()
        for pg, _ in others:
            pg.close()


def test_typing_an_outage_brings_match_attempts_into_open_sky(page, inspector):
    """The sample has open sky for its first 100 s: typing an outage there, key by key, re-runs
    both methods and match attempts appear in it; a wrong entry is refused and changes
    nothing."""
    pg, _ = page
    _, controller, _ = inspector
    before = controller.session
    assert before.outages == ()
    t = before.timeline.match_t
    assert not ((t >= 20.0) & (t <= 80.0)).any(), "the sample already has attempts there"
    status = _status(pg)
    assert status
    pg.get_by_role("tab", name="Parameters").click()
    # viser gives a text input no id of its own: the input on the label's row
    field = (
        pg.locator("label", has_text=re.compile(r"^GNSS outages \(s\)$"))
        .first.locator("xpath=ancestor::div[contains(@class, 'mantine-Flex-root')][1]//input")
        .first
    )
    try:
        field.click()
        # typed like a person (viser sends at most one update per 50 ms, the latest of a burst);
        # the field applies its text when the typing rests
        field.press_sequentially("20:80", delay=150)
        _wait(lambda: controller.outages == ((20.0, 80.0),), 15, "the outages to arrive")
        assert controller.wait_idle(180)
        s = controller.session
        assert s is not before and s.outages == ((20.0, 80.0),)
        t = s.timeline.match_t
        assert ((t >= 20.0) & (t <= 80.0)).any(), "no attempt in the injected outage"
        _wait(lambda: "GNSS removed 20:80 s" in pg.inner_text("body"), 30, "the status line")
        assert _status(pg) not in ("", status)  # the match count changed

        field.press("End")
        field.press_sequentially(", 90", delay=150)  # not START:END
        _wait(lambda: _notified(pg, "GNSS outages not changed"), 15, "the refusal")
        assert "'90' is not START:END in seconds (kept: 20:80)" in pg.inner_text("body")
        assert controller.outages == ((20.0, 80.0),)
        assert controller.wait_idle(30) and controller.session is s
    finally:
        controller.set_outages(())  # the tests below expect the natural sample
        assert controller.wait_idle(180)


def _detour_route(route_path: Path, out: Path) -> Path:
    """The sample route up to 600 m (before its first S-bend turns back), then straight on for
    2 km: the drive leaves it at the bend."""
    import json

    from estimator.nav.frames import LocalFrame

    doc = json.loads(route_path.read_text())
    ll = np.array(doc["features"][0]["geometry"]["coordinates"], np.float64)[:, :2]
    frame = LocalFrame(ll[0, 1], ll[0, 0], 0.0)
    xy = frame.to_enu(ll[:, 1], ll[:, 0], np.zeros(len(ll)))[:, :2]
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    keep = xy[s <= 600.0]
    d = keep[-1] - keep[-2]
    ext = keep[-1] + np.outer(np.arange(100.0, 2001.0, 100.0), d / np.hypot(*d))
    pts = np.vstack([keep, ext])
    geo = frame.to_geodetic(np.column_stack([pts, np.zeros(len(pts))]))
    doc["features"][0]["geometry"]["coordinates"] = [[lon, lat] for lat, lon in geo[:, :2]]
    out.write_text(json.dumps(doc))
    return out


def test_off_route_is_shown_when_the_drive_leaves_the_route(page, inspector, tmp_path):
    """The sample log on a route that goes straight on where the drive turns: the status line
    says off-route, and a frame past the bend says so in the frame label and the match panel."""
    pg, view = page
    _, controller, _ = inspector
    old = controller.session
    route = _detour_route(old.route_path, tmp_path / "detour.route.geojson")
    controller.open(old.log_path, route)
    assert controller.wait_idle(180)
    s = controller.session
    assert s is not old and s.route_path == route.resolve()
    off = s.off_route
    assert off.spans, "the detour is not off-route"
    _wait(lambda: "OFF-ROUTE" in pg.inner_text("body"), 30, "the status line")
    a, b = off.spans[0]
    pg.get_by_role("tab", name="Match").click()
    view.seek(a + 0.5 * (b - a))
    _click(pg, "next ›")
    _wait(lambda: "from the route" in pg.inner_text("body"), 20, "the frame label")
    text = pg.inner_text("body")
    assert re.search(r"GNSS \w+ · OFF-ROUTE \(truth [\d.]+ m from the route\)", text), text[:800]
    assert "the vehicle (truth) is" in text  # the match panel


def test_a_hostile_folder_name_is_shown_as_text_never_run(page):
    """Stored XSS (issue 16): names from the disk reach the page as literal text."""
    pg, _ = page
    pg.get_by_role("tab", name="Files").click()
    _wait(lambda: HOSTILE_NAME in pg.inner_text("body"), 10, "the folder name as text")
    assert pg.evaluate("() => window.pwned === undefined")
    assert pg.locator("img[src='x']").count() == 0
    assert pg.locator("a[href^='javascript']").count() == 0
    pg.get_by_role("tab", name="Match").click()
