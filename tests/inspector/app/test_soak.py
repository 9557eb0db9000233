"""Soak: a long simulated drive run once through the controller (the real estimator), then
stepped end to end through a tab's view (``ClientView.step``: the server-side path of a frame
step - layers, labels, match panel, plot markers - into a headless viser server, as the bench
does), watching that memory does not grow between the first and the second half.

The drive is the simulator's ``long_drive_60min`` scenario cut to its first 20 minutes at
100 Hz IMU (the full 60 minutes at 200 Hz takes minutes to build here); 20 minutes already hold
~24 000 frames and several hundred match attempts to step across.
"""

from __future__ import annotations

import gc
import os
import tracemalloc

import numpy as np
import pytest
from fake_runs import FakeInputs

from inspector.controller import Controller, DataFolders

pytestmark = pytest.mark.slow

DURATION_S = 1200.0
STEPS = 3000
"""frame steps over the whole drive (each step moves the same number of frames)"""


def _rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def test_stepping_a_long_drive_end_to_end_does_not_grow_memory(tmp_path):
    from benchmarks.measures import HeadlessTab
    from estimator.sim import simulate
    from inspector.app import ClientView, InspectorApp
    from inspector.export import headless_server

    sim = simulate("long_drive_60min", imu_rate_hz=100.0, duration_s=DURATION_S)
    inputs = FakeInputs(sim.log(), sim.route(), sim.frame)
    controller = Controller(DataFolders.of(tmp_path), opener=lambda *_: inputs)
    try:
        controller.open(tmp_path / "long.mcap", tmp_path / "long.geojson")
        assert controller.wait_idle(600)
        session = controller.session
        assert session is not None and session.timeline.duration > DURATION_S - 5
        tl = session.timeline
        assert len(tl.match_t) > 100
        stride = max(1, tl.n_frames // STEPS)
        with headless_server() as server:
            app = InspectorApp(server, controller)
            try:
                view = ClientView(app, HeadlessTab(server))  # type: ignore[arg-type]  # a stand-in for viser.ClientHandle
                view.set_session(session)
                for _ in range(50):  # warm up: first overlays, first plot markers
                    view.step(stride)
                view.seek(0.0)
                gc.collect()
                tracemalloc.start()
                half = tl.n_frames // 2
                frames, shown = [], set()
                sizes, rss = [], []
                for phase_end in (half, tl.n_frames - 1):
                    while tl.frame_at(view.playhead.t) < phase_end:
                        view.step(stride)
                        frames.append(tl.frame_at(view.playhead.t))
                        shown.add(view.match.shown[1] if view.match.shown else None)
                    gc.collect()
                    sizes.append(tracemalloc.get_traced_memory()[0] / 2**20)
                    rss.append(_rss_mb())
                tracemalloc.stop()
            finally:
                app.close()
    finally:
        controller.close()

    # stepped end to end, forward only, across the attempts (the match panel changed)
    assert frames[-1] == tl.n_frames - 1 and np.all(np.diff(frames) > 0)
    assert len(frames) >= STEPS * 0.9 and len(shown) > 100
    assert "frame" in view.playback.frame_label.content
    # the second half adds (next to) nothing to what the first half left allocated
    first, second = sizes
    assert second - first < max(2.0, 0.25 * first), f"traced MB after each half: {sizes}"
    assert rss[1] - rss[0] < 50.0, f"RSS MB after each half: {rss}"
