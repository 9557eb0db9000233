"""The playback controls: clicks on a button group are applied once each, in order."""

from __future__ import annotations

import asyncio
import threading

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
