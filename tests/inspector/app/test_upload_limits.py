"""Issue 16, item 5: an upload is bounded by the bytes actually received, not by the size the
client declares; the upload folder has a total cap and is removed however the server exits."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from fake_runs import fake_open, fake_run
from headless_tabs import RecordingTab, deliver, settle
from viser import _messages

from estimator.errors import RoutefuseError
from inspector.app import ClientView, InspectorApp
from inspector.controller import Controller, DataFolders, UploadFolder
from inspector.export import headless_server


@pytest.fixture
def upload_tab(tmp_path, monkeypatch):
    uploads = UploadFolder(max_bytes=1000, max_total_bytes=2500)
    controller = Controller(
        DataFolders.of(tmp_path), uploads=uploads, opener=fake_open, runner=fake_run
    )
    with headless_server() as server:
        app = InspectorApp(server, controller)
        tab = RecordingTab(server, client_id=0)
        monkeypatch.setattr(server.gui, "_resolve_client", lambda _id: tab)
        view = ClientView(app, tab)  # type: ignore[arg-type]  # a stand-in for viser.ClientHandle
        try:
            yield server, tab, view, uploads
        finally:
            view.close()
            app.close()
            controller.close()


def _start(view, transfer, *, size, parts, name="drive.mcap"):
    return _messages.FileTransferStartUpload(
        source_component_uuid=view.files.upload_log._impl.uuid,
        transfer_uuid=transfer,
        filename=name,
        mime_type="application/octet-stream",
        part_count=parts,
        size_bytes=size,
    )


def _part(view, transfer, index, content):
    return _messages.FileTransferPart(
        source_component_uuid=view.files.upload_log._impl.uuid,
        transfer_uuid=transfer,
        part_index=index,
        content=content,
    )


def test_a_transfer_that_sends_more_than_it_declared_is_dropped(upload_tab):
    server, tab, view, uploads = upload_tab
    states = server.gui._current_file_upload_states
    deliver(server, 0, _start(view, "t1", size=1, parts=1000))
    assert "t1" in states
    deliver(server, 0, *(_part(view, "t1", i, b"\x00" * 600) for i in range(3)))
    assert "t1" not in states  # dropped at the first part past the declared size
    assert any(title == "Upload rejected" and "declared" in body for title, body in tab.notes)
    deliver(server, 0, _part(view, "t1", 3, b"\x00" * 600))
    assert "t1" not in states and list(uploads.path.iterdir()) == []


def test_a_transfer_past_the_limit_is_dropped_whatever_it_declared(upload_tab):
    server, tab, view, _ = upload_tab
    states = server.gui._current_file_upload_states
    deliver(server, 0, _start(view, "t2", size=5000, parts=10))
    assert "t2" not in states
    assert any("exceeds the limit" in body for _, body in tab.notes)


def test_uploads_that_fit_are_saved_until_the_folder_is_full(upload_tab):
    server, tab, view, uploads = upload_tab
    for i in range(2):
        deliver(
            server,
            0,
            _start(view, f"ok{i}", size=900, parts=2, name=f"d{i}.mcap"),
            _part(view, f"ok{i}", 0, b"\x01" * 450),
            _part(view, f"ok{i}", 1, b"\x01" * 450),
        )
        settle(server)
    assert len(list(uploads.path.iterdir())) == 2
    assert uploads.used_bytes() == 1800
    deliver(server, 0, _start(view, "full", size=900, parts=1, name="d2.mcap"))
    assert "full" not in server.gui._current_file_upload_states
    assert any("upload folder" in body for _, body in tab.notes)
    with pytest.raises(RoutefuseError, match="upload folder"):
        uploads.save("d3.mcap", b"x" * 900)


def test_transfers_in_flight_count_against_the_folder_cap(upload_tab):
    server, _, view, _ = upload_tab
    states = server.gui._current_file_upload_states
    for i in range(3):  # 3 x 900 declared > 2500
        deliver(server, 0, _start(view, f"f{i}", size=900, parts=2, name=f"f{i}.mcap"))
    assert [t for t in ("f0", "f1", "f2") if t in states] == ["f0", "f1"]


_HOLDER = """
import signal, sys, time
from inspector.folders import UploadFolder, exit_on_termination_signals
# Ctrl+C as a shell's foreground process gets it (started from a background job, this
# process would inherit SIGINT ignored)
signal.signal(signal.SIGINT, signal.default_int_handler)
exit_on_termination_signals()
up = UploadFolder()
(up.path / "part.mcap").write_bytes(b"x")
print(up.path, flush=True)
if sys.argv[1] == "wait":
    time.sleep(60)
"""


@pytest.mark.parametrize("how", ["return", "SIGTERM", "SIGHUP", "SIGINT"])
def test_the_upload_folder_is_removed_however_the_process_ends(how):
    root = Path(__file__).resolve().parents[3]
    proc = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(_HOLDER), "return" if how == "return" else "wait"],
        cwd=root,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    folder = Path(proc.stdout.readline().strip())
    if how != "return":
        assert folder.is_dir()
        os.kill(proc.pid, getattr(signal, how))
    proc.wait(30)
    deadline = time.monotonic() + 5
    while folder.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not folder.exists()
