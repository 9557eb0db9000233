"""The match panel text (the rest of the app is driven in tests/e2e)."""

from __future__ import annotations

import asyncio
import threading

from fake_runs import make_run

from inspector.app import match_markdown


def test_match_panel_lists_every_gate_and_marks_the_failed_one():
    run = make_run(rejected=(2,))
    text = match_markdown(run.matches[2], t_rel=50.0, total=5)
    assert "Attempt #2 of 5 at t = 50.00 s: REJECTED" in text
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    gate_rows = {r.split("|")[1].strip(): r for r in rows[1:4]}
    assert set(gate_rows) == {"min_pairs", "heading_cos", "residual_m"}
    assert "✗ **FAILED**" in gate_rows["residual_m"] and "<= 3.000" in gate_rows["residual_m"]
    assert "✓ passed" in gate_rows["min_pairs"]
    assert "| residual (RMS) | 7.500 m |" in text
    assert "| correction E, N | (0.00, 0.00) m" in text


def test_match_panel_for_an_accepted_attempt_and_for_none():
    run = make_run(rejected=())
    text = match_markdown(run.matches[0], t_rel=40.0, age_s=1.5, total=5)
    assert "ACCEPTED" in text and "(1.50 s ago)" in text and "FAILED" not in text
    assert "| correction E, N | (0.00, -2.00) m" in text
    assert "No match attempt" in match_markdown(None)


def test_plot_payloads_carry_their_own_titles_units_and_time_marker():
    from fake_runs import FakeInputs, make_route

    from inspector.plots import DeviationPlot

    base, prop = make_run(drift=30, method="baseline"), make_run()
    plot = DeviationPlot.build(FakeInputs(None, make_route(), prop.frame), base, prop)
    assert plot.kinds == ("position", "heading")  # no truth in these runs
    titles = set()
    for which in plot.kinds:
        kw = plot.uplot(which, 50.0)
        titles.add(kw["title"])
        xs, _, _, shade, now = kw["data"]
        assert len({len(a) for a in kw["data"]}) == 1 and len(kw["series"]) == 5
        k = int(abs(xs - 50.0).argmin())
        assert now.max() == 2.0 and xs[now.argmax()] == 50.0  # the marker spans the plot
        assert shade[k] == 1.0 and shade[0] == 0.0  # 50 s is inside the outage
        unit = "deg" if which == "heading" else "m"
        assert kw["series"][1]["label"] == f"baseline [{unit}]"
    assert len(titles) == 2
    assert plot.position[0].max() > 20 > plot.position[1].max()  # baseline drifts 30 m


def test_two_quick_clicks_step_by_each_button_pressed(tmp_path, monkeypatch):
    """viser stores a button group's pressed label on the shared handle; two clicks that arrive
    while its thread pool is busy must still each move by their own button ("next ›" then
    "10 »": 11 frames, not 20)."""
    from fake_runs import FakeInputs
    from viser import _messages

    from benchmarks.harness import _HeadlessTab
    from estimator.sim import simulate
    from inspector.app import ClientView, InspectorApp
    from inspector.controller import Controller, DataFolders
    from inspector.export.replay import headless_server

    sim = simulate("short_tunnel", imu_rate_hz=100.0)
    inputs = FakeInputs(sim.log(), sim.route(), sim.frame)
    controller = Controller(DataFolders.of(tmp_path), opener=lambda *_: inputs)
    try:
        controller.open(tmp_path / "short.mcap", tmp_path / "short.geojson")
        assert controller.wait_idle(300) and controller.session is not None
        with headless_server() as server:
            app = InspectorApp(server, controller)
            tab = _HeadlessTab(server)
            view = ClientView(app, tab)  # type: ignore[arg-type]
            try:
                view.set_session(controller.session)
                tl = controller.session.timeline
                view.seek(tl.duration / 2)
                start = tl.frame_at(view.playhead.t)
                monkeypatch.setattr(server.gui, "_resolve_client", lambda _id: tab)
                uuid = view.step_buttons._impl.uuid

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
                view._clicks.submit(lambda: None).result(timeout=30)
                assert tl.frame_at(view.playhead.t) == start + 11
            finally:
                view.close()
                app.close()
    finally:
        controller.close()
