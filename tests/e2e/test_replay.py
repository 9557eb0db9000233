"""The exported replay.html in headless Chromium, opened from file:// with the network off: the
scene renders, playing advances the vehicle and every clock together in log time, the panel
shows the gate table of the attempt on screen, "next refused" jumps there, and a click on the
deviation plot goes to that time. The log's route has a trap (a stretch of the tunnel drawn
along a parallel bore 25 m away), so there are refused attempts beside accepted ones."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1400, "height": 850}
TIMEOUT_MS = 180_000
"""generous: software WebGL on two shared cores"""
PANEL_WIDTH_PX = 470
"""the panel's width (templates/replay_panel.html): the scene is left of it"""


def _trap_route(sim, route_path: Path, out: Path) -> Path:
    """The simulated route with the tunnel's second half drawn 25 m to the side."""
    from estimator.sim.sdmap import parallel_bore

    route = sim.route()
    ((a, b),) = sim.tunnels
    truth = sim.truth
    xy = np.array(
        [
            [np.interp(t, truth.t, truth.position[:, i]) for i in range(2)]
            for t in (a + 0.55 * (b - a), b + 5)
        ]
    )
    s0, s1 = route.project(xy).s
    moved = parallel_bore(route, float(s0), float(s1), 25.0, ramp_m=40.0)
    geo = sim.frame.to_geodetic(np.column_stack([moved.xy, np.zeros(len(moved.xy))]))
    doc = json.loads(route_path.read_text())
    doc["features"][0]["geometry"]["coordinates"] = [
        [round(float(lon), 8), round(float(lat), 8)] for lat, lon in geo[:, :2]
    ]
    out.write_text(json.dumps(doc))
    return out


@pytest.fixture(scope="module")
def replay(tmp_path_factory) -> Path:
    from estimator.sim import simulate
    from inspector.export import ReplayOptions, export_log

    sim_dir = tmp_path_factory.mktemp("sim")
    sim = simulate("short_tunnel", seed=1, duration_s=75.0)
    log, route = sim.write(sim_dir)
    trap = _trap_route(sim, Path(route), sim_dir / "trap.route.geojson")
    result = export_log(
        log, trap, tmp_path_factory.mktemp("export"), replay=ReplayOptions(time_lapse=2.0)
    )
    return result.out_dir / "replay.html"


@pytest.fixture(scope="module")
def attempts(replay) -> list[dict[str, str]]:
    """The export's own list of attempts (matches.csv), to check the page against."""
    with (replay.parent / "matches.csv").open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def page(replay, browser):
    context = browser.new_context(viewport=VIEWPORT, offline=True)
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    failed: list[str] = []
    errors: list[str] = []
    page.on("requestfailed", lambda r: failed.append(r.url))
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(replay.as_uri())
    page.wait_for_selector("canvas", state="visible")
    page.wait_for_selector("body[data-replay-ready=true]")
    # the "software WebGL" notice would count as drawn pixels
    page.add_style_tag(content=".mantine-Notification-root { display: none !important; }")
    page.failed_requests = failed  # type: ignore[attr-defined]
    page.errors = errors  # type: ignore[attr-defined]
    yield page
    context.close()


def _panel_time(page) -> float:
    """Log seconds, from the panel's time slider."""
    return float(page.locator("#rf-time").input_value())


def _scene_time(page) -> float:
    """Seconds into viser's recording (its hidden scrubber)."""
    return float(page.locator("[role=slider]").get_attribute("aria-valuenow"))


def _scene_pixels(page) -> np.ndarray:
    """The 3D view below the clock label, left of the panel, as RGB floats."""
    img = matplotlib.image.imread(io.BytesIO(page.screenshot()), format="png")[..., :3]
    h = img.shape[0]
    return img[int(0.12 * h) : int(0.95 * h), : VIEWPORT["width"] - PANEL_WIDTH_PX]


def _route_and_track(pixels: np.ndarray) -> tuple[int, int]:
    """Pixels of the route's grey and of the proposed trajectory's blue."""
    grey = np.all(np.abs(pixels - 120 / 255) < 0.08, axis=-1)
    blue = (pixels[..., 2] > 0.7) & (pixels[..., 0] < 0.45)
    return int(grey.sum()), int(blue.sum())


def _pause(page) -> None:
    if page.locator("#rf-play").text_content() == "Pause":
        page.click("#rf-play")


def test_scene_renders_from_file(page):
    assert page.url.startswith("file://")
    assert page.failed_requests == [] and page.errors == []
    for _ in range(30):  # software WebGL may take a while for the first frame
        pixels = _scene_pixels(page)
        grey, blue = _route_and_track(pixels)
        if grey > 100 and blue > 30:
            break
        page.wait_for_timeout(1000)
    drawn = np.any(np.abs(pixels - pixels[0, 0]) > 0.1, axis=-1)
    assert drawn.mean() > 0.003, "the 3D view is blank"
    assert grey > 100, "no route drawn"
    assert blue > 30, "no proposed trajectory drawn"


def test_playing_advances_the_scene_and_every_clock_in_log_time(page):
    if page.locator("#rf-play").text_content() == "Play":
        page.click("#rf-play")
    before, shot_before = _panel_time(page), _scene_pixels(page)
    page.wait_for_timeout(2500)
    _pause(page)
    after, shot_after = _panel_time(page), _scene_pixels(page)
    # it loops: either it moved forward, or it wrapped around to the start
    assert after > before + 0.5 or after < before - 5.0
    assert abs(_scene_time(page) - after) < 0.01  # viser's clock is the log's too
    clock = page.locator("#rf-clock").text_content()
    assert clock.startswith(f"log time {after:.1f} s")
    changed = np.any(np.abs(shot_after - shot_before) > 0.15, axis=-1)
    assert changed.sum() > 20, "playing did not change the scene"


def test_next_refused_shows_its_gate_table(page, attempts):
    """From the start, "next refused" twice: the second refused attempt of matches.csv, with
    the gate that refused it marked, and the scene at its time."""
    refused = [a for a in attempts if a["accepted"] == "0"]
    assert len(refused) >= 2 and any(a["accepted"] == "1" for a in attempts)
    page.locator("#rf-time").fill("0")
    page.click("#rf-next-refused")
    page.click("#rf-next-refused")
    second = refused[1]
    t = float(second["t_s"])
    assert _panel_time(page) == pytest.approx(t, abs=0.05)
    assert _scene_time(page) == pytest.approx(t, abs=0.01)
    title = page.locator("#rf-attempt-title").text_content()
    assert title == f"Attempt #{second['index']} at {t:.1f} s: {second['verdict']}"
    failed = page.locator("#rf-gates tr.rf-failed td:first-child").all_text_contents()
    gates = [
        c.removesuffix("_verdict")
        for c, v in second.items()
        if c.endswith("_verdict") and v == "fail"
    ]
    assert failed and failed == gates
    assert "FAILED" in page.locator("#rf-gates tr.rf-failed").first.text_content()
    assert page.locator("#rf-fit").text_content().startswith("rotation ")
    page.click("#rf-prev-refused")
    assert _panel_time(page) == pytest.approx(float(refused[0]["t_s"]), abs=0.05)


def test_the_gate_table_follows_the_time(page, attempts):
    """Dragging the time slider to an accepted attempt shows that attempt, to a time with no
    attempt shows none."""
    accepted = next(a for a in attempts if a["accepted"] == "1")
    page.locator("#rf-time").fill(accepted["t_s"])
    assert (
        page.locator("#rf-attempt-title")
        .text_content()
        .startswith(f"Attempt #{accepted['index']} at ")
    )
    assert page.locator("#rf-gates tr.rf-failed").count() == 0
    page.locator("#rf-time").fill("5")
    assert page.locator("#rf-attempt-title").text_content() == "No match attempt on screen"
    assert abs(_scene_time(page) - 5.0) < 0.01


def test_a_click_on_the_deviation_plot_goes_to_that_time(page):
    data = json.loads(page.locator("#routefuse-replay-data").text_content())
    strip = data["strip"]
    img = page.locator("#rf-strip")
    box = img.bounding_box()
    scale = box["width"] / strip["width_px"]
    target = strip["t_lo"] + 0.8 * (strip["t_hi"] - strip["t_lo"])
    x = strip["x_left_px"] + 0.8 * (strip["x_right_px"] - strip["x_left_px"])
    page.mouse.click(box["x"] + x * scale, box["y"] + box["height"] / 2)
    assert _panel_time(page) == pytest.approx(target, abs=0.5)
    cursor = page.locator("#rf-cursor").bounding_box()
    assert cursor["x"] == pytest.approx(box["x"] + x * scale, abs=3)


def test_the_space_bar_plays_and_pauses(page):
    _pause(page)
    page.locator("#rf-strip").click()
    page.keyboard.press("Space")
    assert page.locator("#rf-play").text_content() == "Pause"
    page.keyboard.press("Space")
    assert page.locator("#rf-play").text_content() == "Play"
    page.click("#rf-play")  # the button keeps the focus: space presses it, once
    assert page.locator("#rf-play").text_content() == "Pause"
    page.keyboard.press("Space")
    assert page.locator("#rf-play").text_content() == "Play"
    before = _scene_time(page)
    page.wait_for_timeout(1000)
    assert _scene_time(page) == before  # viser's own player did not start either


def test_the_legend_names_every_colour(page):
    from inspector.layers import legend_entries

    shown = page.locator("#rf-legend li").all_text_contents()
    assert [s.strip() for s in shown] == [meaning for _, meaning in legend_entries()]


def test_the_page_title_names_the_log_escaped(tmp_path, browser):
    """The replay's browser tab said "Viser" whatever the log: ten replays open were ten tabs
    of the same name. It names the log and route, as text."""
    from estimator.sim import simulate
    from inspector.export import ReplayOptions, export_log

    log, route = simulate("short_tunnel", seed=1, duration_s=60.0).write(tmp_path)
    hostile = tmp_path / "tunnel <b>x<b> & é.mcap"  # no "/" in a file name
    Path(log).rename(hostile)
    result = export_log(hostile, route, tmp_path / "export", replay=ReplayOptions(max_frames=20))
    context = browser.new_context(viewport=VIEWPORT, offline=True)
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    page.goto((result.out_dir / "replay.html").as_uri())
    page.wait_for_selector("body[data-replay-ready=true]")
    name = f"{hostile.name} on {Path(route).name}"
    assert page.title() == f"routefuse replay: {name}"
    assert page.locator("h1", has_text="tunnel").first.inner_text() == name
    assert page.locator("h1 b").count() == 0  # the name's markup is text, not bold
    context.close()
