"""Issue 16, items 3 and 5, over a real websocket: a client of the inspector's own origin that
sends values no control offers, and an upload that lies about its size, changes nothing shared;
a browser tab opened afterwards shows the session and the method in effect."""

from __future__ import annotations

import contextlib
import threading
import time
from pathlib import Path

import msgspec
import pytest
import viser
from _browser import free_port
from _browser import wait_until as _wait
from viser import _messages
from websockets.sync.client import connect

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "sample_logs" / "long_tunnel.mcap"
UPLOAD_LIMIT = 1_000_000


@pytest.fixture(scope="module")
def inspector(tmp_path_factory):
    from inspector.cli.serve import start

    route = SAMPLE.with_name("long_tunnel.route.geojson")
    if not (SAMPLE.exists() and route.exists()):
        pytest.skip("the bundled long-tunnel sample is not in this checkout")
    server, controller, app = start(
        host="127.0.0.1",
        port=free_port(),
        data_dirs=[tmp_path_factory.mktemp("data")],
        log=SAMPLE,
        route=route,
        max_upload_bytes=UPLOAD_LIMIT,
    )
    try:
        assert controller.wait_idle(300), "the sample did not load"
        assert controller.session is not None
        yield server, controller, app
    finally:
        app.close()
        controller.close()
        server.stop()


def _drain(ws) -> None:
    """Read what the server sends, as a browser would (until the socket closes)."""
    with contextlib.suppress(Exception):
        while True:
            ws.recv()


def _send(ws, message: _messages.Message) -> None:
    ws.send(msgspec.msgpack.encode(message.as_serializable_dict()))


def test_a_misbehaving_client_changes_nothing_shared_and_a_new_tab_works(browser, inspector):
    server, controller, app = inspector
    url = f"ws://127.0.0.1:{server.get_port()}"
    before = {v.client.client_id for v in app.views()}
    params, session = controller.params, controller.session
    with connect(
        url,
        origin=f"http://127.0.0.1:{server.get_port()}",
        subprotocols=[f"viser-v{viser.__version__}"],
        max_size=None,
    ) as ws:
        drain = threading.Thread(target=_drain, args=(ws,), daemon=True)
        drain.start()
        # viser counts a client as connected once it reports its camera, as a browser does
        camera = _messages.ViewerCameraMessage(
            (1.0, 0.0, 0.0, 0.0),
            (0.0, 0.0, 10.0),
            1.0,
            0.1,
            1000.0,
            900,
            1400,
            (0.0, 0.0, 0.0),
            (0.0, 0.0, 1.0),
        )
        _send(ws, camera)
        view = _wait(
            lambda: [v for v in app.views() if v.client.client_id not in before], 30, "its view"
        )[0]
        widget = view.parameters.widget
        for handle, value in (
            (view.parameters.method, "evil"),
            (widget("sensors.gnss_lever_arm_m"), [float("nan"), 0.0, 0.0]),
            (widget("sensors.initial_heading_deg"), "inf"),
            (view.files.log_choice, "../../etc/passwd"),
            (view.playback.speed, "nanx"),
            (view.playback.time_slider, float("inf")),
        ):
            _send(ws, _messages.GuiUpdateMessage(handle._impl.uuid, {"value": value}))
        uploads = view.client.gui._current_file_upload_states
        upload = view.files.upload_log._impl.uuid
        _send(ws, _messages.FileTransferStartUpload(upload, "lie", "x.mcap", "", 100, 1))
        for i in range(3):
            _send(ws, _messages.FileTransferPart(upload, "lie", i, b"\0" * 600_000))
        _wait(lambda: view.parameters.method.value == "proposed", 10, "the method shown again")
        _wait(lambda: "lie" not in uploads, 10, "the lying upload dropped")
        time.sleep(1.0)
        assert controller.params == params and controller.method == "proposed"
        assert controller.session is session and not controller.busy
        assert view.playback.speed.value == "5x" and view.playhead.speed == 5.0
        assert list(controller.uploads.path.iterdir()) == []

        page = browser.new_page(viewport={"width": 1400, "height": 900})
        try:
            page.set_default_timeout(90_000)
            page.goto(f"http://127.0.0.1:{server.get_port()}")
            _wait(lambda: "match attempts" in page.inner_text("body"), 60, "the session")
            page.get_by_role("tab", name="Parameters").click()
            _wait(lambda: page.locator("input[value='proposed']").count(), 10, "the method")
        finally:
            page.close()


@contextlib.contextmanager
def _foreign_site(html: str):
    """Another web site on this machine (another port: another origin) serving one page."""
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    body = html.encode()

    class Page(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    site = ThreadingHTTPServer(("127.0.0.1", free_port()), Page)
    thread = threading.Thread(target=site.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{site.server_address[1]}/"
    finally:
        site.shutdown()
        site.server_close()


def test_the_page_loads_under_its_policy_and_no_other_site_can_frame_it(browser, inspector):
    """The inspector's page connects to its own server under ``connect-src 'self'`` (nothing
    the page needs is refused); another site's page that frames it, to put its buttons under
    the user's clicks, gets no inspector in the frame and no connection."""
    server, _controller, app = inspector
    port = server.get_port()
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    refused: list[str] = []
    page.on("console", lambda m: refused.append(m.text) if "Content Security" in m.text else None)
    try:
        page.set_default_timeout(90_000)
        page.goto(f"http://127.0.0.1:{port}")
        _wait(lambda: "match attempts" in page.inner_text("body"), 60, "the session")
        assert refused == []
    finally:
        page.close()

    before = {v.client.client_id for v in app.views()}
    frame_html = f'<p>win a prize</p><iframe src="http://127.0.0.1:{port}/" width=900 height=600>'
    with _foreign_site(frame_html) as url:
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        try:
            page.goto(url)
            time.sleep(5.0)
            assert "win a prize" in page.inner_text("body")
            framed = [f for f in page.frames if f != page.main_frame]
            assert framed, "the frame element is there"
            for f in framed:
                text = ""
                with contextlib.suppress(Exception):  # a blocked frame may have no body
                    text = f.inner_text("body", timeout=2_000)
                assert "match attempts" not in text
        finally:
            page.close()
    assert {v.client.client_id for v in app.views()} <= before


def test_an_address_pointing_the_page_at_another_server_is_refused(browser, inspector):
    server, _controller, app = inspector
    before = {v.client.client_id for v in app.views()}
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    try:
        response = page.goto(f"http://127.0.0.1:{server.get_port()}/?websocket=ws://127.0.0.1:9")
        assert response is not None and response.status == 400
        assert "connects only to its own server" in page.inner_text("body")
    finally:
        page.close()
    assert {v.client.client_id for v in app.views()} <= before
