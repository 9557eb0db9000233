"""The Files tab's route line: a route file holding several lines offers them in a 'route line'
dropdown, opening it without one says to choose there, and the line chosen is opened. Values
go in as viser delivers a browser's (see test_browser_values)."""

from __future__ import annotations

import shutil
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from fake_runs import HOSTILE_LINE, MONACO_LOG, MONACO_ROUTE, fake_run, two_line_route
from headless_tabs import RecordingTab, deliver
from viser import _messages

from inspector.app import InspectorApp
from inspector.app.files import CHOOSE_LINE, loaded_markdown
from inspector.controller import Controller, DataFolders
from inspector.export import headless_server


@pytest.fixture
def files_tab(tmp_path, monkeypatch):
    d = tmp_path / "data"
    d.mkdir()
    shutil.copy(MONACO_LOG, d / "monaco.mcap")
    shutil.copy(MONACO_ROUTE, d / "monaco.route.geojson")
    two_line_route(d / "two.route.geojson")
    controller = Controller(DataFolders.of(d), runner=fake_run)
    controller.open_named("data/monaco.mcap", "data/monaco.route.geojson")
    assert controller.wait_idle(60) and controller.session is not None
    with headless_server() as server:
        app = InspectorApp(server, controller)
        tab = RecordingTab(server, client_id=1)
        monkeypatch.setattr(server.gui, "_resolve_client", lambda cid: tab)
        app._connect(tab)  # type: ignore[arg-type]  # a stand-in for viser.ClientHandle
        (view,) = app.views()  # told of the controller's news, as a browser's tab is
        try:
            yield server, controller, tab, view
        finally:
            view.close()
            app.close()
            controller.close()


def _until(predicate, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def _send(server, tab, handle, value) -> None:
    deliver(server, tab.client_id, _messages.GuiUpdateMessage(handle._impl.uuid, {"value": value}))


def test_route_line_is_offered_for_a_file_of_several_lines_and_the_chosen_one_opens(files_tab):
    server, controller, tab, view = files_tab
    files = view.files
    first = controller.session
    assert not files.route_line.visible  # the loaded route has one line
    _send(server, tab, files.route_choice, "data/two.route.geojson")
    assert files.route_line.visible
    assert files.route_line.options == (CHOOSE_LINE, f"0: {HOSTILE_LINE}", "1: east")
    assert files.route_line.value == CHOOSE_LINE

    _send(server, tab, files.open_button, True)  # opened without a line
    assert controller.wait_idle(60) and controller.session is first
    title, body = tab.notes[-1]
    assert title == "Kept the previous session"
    assert body.endswith(
        "two.route.geojson: the file has 2 lines (0: <img src=x onerror=alert(1)>, 1: east); "
        "choose one under 'route line' in the Files tab, then press 'open'"
    )

    _send(server, tab, files.route_line, "1: east")
    _send(server, tab, files.open_button, True)
    assert controller.wait_idle(60)
    s = controller.session
    assert s is not first and s.route_feature == 1 and s.inputs.route.name == "east"
    _until(lambda: "line **1: east**" in files.loaded.content)  # the session reached the tab
    assert files.route_line.value == "1: east" and files.route_line.visible

    _send(server, tab, files.route_choice, "data/monaco.route.geojson")  # one line again
    assert not files.route_line.visible


def test_a_route_line_the_file_does_not_have_is_refused(files_tab):
    server, _, tab, view = files_tab
    files = view.files
    _send(server, tab, files.route_choice, "data/two.route.geojson")
    _send(server, tab, files.route_line, "7: evil")
    assert (
        tab.notes[-1][0] == "Refused"
        and "'7: evil' is not a line of data/two.route.geojson" in (tab.notes[-1][1])
    )
    assert files.route_line.value == CHOOSE_LINE


def test_a_line_name_is_escaped_where_the_files_tab_shows_it(files_tab):
    _, controller, _, _ = files_tab
    controller.open_named("data/monaco.mcap", "data/two.route.geojson", route_feature=0)
    assert controller.wait_idle(60) and controller.session.route_feature == 0
    shown = loaded_markdown(controller.session)
    assert "<img" not in shown and "&lt;img src=x onerror=alert\\(1\\)&gt;" in shown


def test_each_loaded_file_has_its_full_path_escaped_on_a_line_beneath_its_name():
    hostile = "<img src=x onerror=alert(1)>"
    session = SimpleNamespace(
        route_feature=None,
        log_name=f"{hostile}.mcap",
        log_path=Path(f"/data/{hostile}/{hostile}.mcap"),
        route_name="drive.route.geojson",
        route_path=Path(f"/data/{hostile}/drive.route.geojson"),
    )
    shown = loaded_markdown(session)  # type: ignore[arg-type]
    assert "<img" not in shown and shown.count("&lt;img src=x onerror=alert\\(1\\)&gt;") == 4
    log_item, route_item = shown.split("\n")[-2:]
    assert log_item.index("**&lt;img") < log_item.index("<br>") < log_item.index("/data/")
    assert route_item.index("**drive") < route_item.index("<br>") < route_item.index("/data/")
