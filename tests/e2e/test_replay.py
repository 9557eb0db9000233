"""The exported replay.html in headless Chromium, opened from file:// with the network off: the
scene renders, playback advances the vehicle and the clock, and scrubbing shows another instant."""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1000, "height": 700}
TIMEOUT_MS = 180_000
"""generous: software WebGL on two shared cores"""


@pytest.fixture(scope="module")
def replay(tmp_path_factory) -> Path:
    from estimator.sim import simulate
    from inspector.export import ReplayOptions, export_log

    sim_dir = tmp_path_factory.mktemp("sim")
    log, route = simulate("short_tunnel", seed=1, duration_s=60.0).write(sim_dir)
    result = export_log(
        log, route, tmp_path_factory.mktemp("export"), replay=ReplayOptions(time_lapse=2.0)
    )
    return result.out_dir / "replay.html"


@pytest.fixture(scope="module")
def page(replay, browser):
    context = browser.new_context(viewport=VIEWPORT, offline=True)
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    failed: list[str] = []
    page.on("requestfailed", lambda r: failed.append(r.url))
    page.goto(replay.as_uri())
    page.wait_for_selector("canvas", state="visible")
    page.locator("[role=slider]").wait_for(state="attached")
    # the "software WebGL" notice would count as drawn pixels
    page.add_style_tag(content=".mantine-Notification-root { display: none !important; }")
    page.failed_requests = failed  # type: ignore[attr-defined]
    yield page
    context.close()


def _player_time(page) -> float:
    """Seconds into the recording, from the scrubber."""
    return float(page.locator("[role=slider]").get_attribute("aria-valuenow"))


def _scene_pixels(page) -> np.ndarray:
    """The 3D view below the clock label and above the player bar, as RGB floats."""
    img = matplotlib.image.imread(io.BytesIO(page.screenshot()), format="png")[..., :3]
    h = img.shape[0]
    return img[int(0.12 * h) : int(0.9 * h)]


def _seek(page, fraction: float) -> None:
    track = page.locator(".mantine-Slider-root").bounding_box()
    assert track is not None, "no scrubber"
    page.mouse.click(track["x"] + fraction * track["width"], track["y"] + track["height"] / 2)


def _route_and_track(pixels: np.ndarray) -> tuple[int, int]:
    """Pixels of the route's grey and of the proposed trajectory's blue."""
    grey = np.all(np.abs(pixels - 120 / 255) < 0.08, axis=-1)
    blue = (pixels[..., 2] > 0.7) & (pixels[..., 0] < 0.45)
    return int(grey.sum()), int(blue.sum())


def test_scene_renders_from_file(page):
    assert page.url.startswith("file://")
    assert page.failed_requests == []
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


def test_playback_advances(page):
    before, shot_before = _player_time(page), _scene_pixels(page)
    page.wait_for_timeout(2500)
    after, shot_after = _player_time(page), _scene_pixels(page)
    # the player loops: either it moved forward, or it wrapped around to the start
    assert after > before + 0.5 or after < before - 5.0
    changed = np.any(np.abs(shot_after - shot_before) > 0.15, axis=-1)
    assert changed.sum() > 20, "playing did not change the scene"


def test_scrubbing_moves_the_vehicle(page):
    page.locator(".mantine-Paper-root button").first.click(force=True)  # pause
    _seek(page, 0.15)
    page.wait_for_timeout(1500)
    early_t, early = _player_time(page), _scene_pixels(page)
    page.wait_for_timeout(1000)
    assert _player_time(page) == early_t, "pause did not stop the player"
    _seek(page, 0.75)
    page.wait_for_timeout(1500)
    late_t, late = _player_time(page), _scene_pixels(page)
    assert late_t > early_t + 10.0
    changed = np.any(np.abs(late - early) > 0.15, axis=-1)
    assert changed.sum() > 50, "nothing moved between the two instants"
