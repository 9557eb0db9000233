"""The playback controls: clicks on a button group are applied once each, in order."""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from fake_runs import FakeInputs
from viser import _messages

from benchmarks.measures import HeadlessTab
from estimator.sim import simulate
from inspector.app import ClientView, InspectorApp
from inspector.controller import Controller, DataFolders
from inspector.export import headless_server


def test_two_quick_clicks_step_by_each_button_pressed(tmp_path, monkeypatch):
    """viser stores a button group's pressed label on the shared handle; two clicks that arrive
    while its thread pool is busy must still each move by their own button ("next ›" then
    "10 »": 11 frames, not 20)."""
    sim = simulate("short_tunnel", imu_rate_hz=100.0)
    inputs = FakeInputs(sim.log(), sim.route(), sim.frame)
    controller = Controller(DataFolders.of(tmp_path), opener=lambda *_: inputs)
    try:
        controller.open(tmp_path / "short.mcap", tmp_path / "short.geojson")
        assert controller.wait_idle(300) and controller.session is not None
        with headless_server() as server:
            app = InspectorApp(server, controller)
            tab = HeadlessTab(server)
            view = ClientView(app, tab)  # type: ignore[arg-type]  # a stand-in for viser.ClientHandle
            try:
                view.set_session(controller.session)
                tl = controller.session.timeline
                view.seek(tl.duration / 2)
                start = tl.frame_at(view.playhead.t)
                monkeypatch.setattr(server.gui, "_resolve_client", lambda _id: tab)
                uuid = view.playback.step_buttons._impl.uuid

                async def click_twice() -> None:
                    for label in ("next ›", "10 »"):
                        message = _messages.GuiUpdateMessage(uuid, {"value": label})
                        await server.gui._handle_gui_updates(tab.client_id, message)

                pool = server.gui._thread_executor
                busy = threading.Event()
                for _ in range(pool._max_workers):  # other callbacks still running
                    pool.submit(busy.wait, 30)
                clicker = threading.Thread(target=asyncio.run, args=(click_twice(),))
                clicker.start()  # its own event loop: the browser tests leave one running here
                clicker.join(30)
                busy.set()
                pool.submit(lambda: None).result(timeout=30)
                view.playback.clicks.submit(lambda: None).result(timeout=30)
                assert tl.frame_at(view.playhead.t) == start + 11
            finally:
                view.close()
                app.close()
    finally:
        controller.close()


def test_the_status_line_lists_the_logs_warnings_escaped_and_bounded():
    from inspector.app.playback import MAX_WARNINGS_SHOWN, status_markdown, warnings_markdown

    assert warnings_markdown(()) == ""
    hostile = "IMU <img src=x onerror=alert(1)>: clock jumps back " + "x" * 1000
    warned = (*(f"GNSS: warning {k}" for k in range(MAX_WARNINGS_SHOWN + 2)), hostile)
    text = warnings_markdown(warned)
    assert f"{len(warned)} warnings about this log" in text
    assert "GNSS: warning 0" in text and "and 3 more" in text
    one = warnings_markdown((hostile,))
    assert "<img" not in one and len(one) < 500
    timeline = SimpleNamespace(
        duration=60.0, n_frames=600, match_t=np.zeros(3), match_accepted=np.ones(3, bool)
    )
    session = SimpleNamespace(
        log_name="drive.mcap",
        route_name="drive.route.geojson",
        timeline=timeline,
        outages=(),
        off_route=None,
        proposed=SimpleNamespace(
            method="proposed",
            warnings=("wheel speed looks like km/h",),
            degraded_intervals=(),
            matches=(),
            dropped_fix_times=(),
            exits=(),
        ),
    )
    line = status_markdown(session)  # type: ignore[arg-type]
    assert "1 warning about this log" in line and "km/h" in line


def test_a_run_pinned_on_another_drive_is_not_compared():
    from inspector.app.compare import compare_markdown, same_drive

    def session(version, log):
        return SimpleNamespace(
            version=version,
            log_path=Path(f"/data/{log}"),
            route_path=Path("/data/r.geojson"),
            log_name=log,
            metrics=(("position deviation RMSE [m]", "1.0", "2.0"),),
            proposed=SimpleNamespace(matches=(), t0=0.0),
        )

    a, b, other = session(1, "a.mcap"), session(2, "a.mcap"), session(3, "b.mcap")
    assert same_drive(a, b) and not same_drive(a, other)
    assert "nothing to compare" in compare_markdown(a, other)
    text = compare_markdown(a, b)
    assert "| position deviation RMSE \\[m\\] | 2.0 | &ensp;2.0 | &ensp;0.0 |" in text  # no sign
    assert "0 attempts" in text


def test_b_minus_a_is_shown_to_the_precision_of_a_and_b():
    """A count's difference is '+2', not '+2.000' (which also ran into B's column), and a
    figure shown to 0.1 m is not differenced to the millimetre."""
    from inspector.app.compare import compare_markdown

    def session(version, metrics):
        return SimpleNamespace(
            version=version,
            log_path=Path("/data/a.mcap"),
            route_path=Path("/data/r.geojson"),
            log_name="a.mcap",
            metrics=metrics,
            proposed=SimpleNamespace(matches=(), t0=0.0),
        )

    rows_a = (
        ("max position deviation [m]", "", "27.2"),
        ("mean position deviation [m]", "", "5.055"),
        ("rejected first by residual", "", "19"),
        ("match attempts (accepted / rejected)", "", "352 (283 / 69)"),
    )
    rows_b = (
        ("max position deviation [m]", "", "26.9"),
        ("mean position deviation [m]", "", "5.101"),
        ("rejected first by residual", "", "21"),
        ("match attempts (accepted / rejected)", "", "352 (282 / 70)"),
    )
    text = compare_markdown(session(1, rows_a), session(2, rows_b))
    # B and B - A each after an en space: the columns ran together ('5.0550.000', '21+2')
    assert "| max position deviation \\[m\\] | 27.2 | &ensp;26.9 | &ensp;-0.3 |" in text
    assert "| mean position deviation \\[m\\] | 5.055 | &ensp;5.101 | &ensp;+0.046 |" in text
    assert "| rejected first by residual | 19 | &ensp;21 | &ensp;+2 |" in text
    assert "| 352 (283 / 69) | &ensp;352 (282 / 70) | &ensp; |" in text
