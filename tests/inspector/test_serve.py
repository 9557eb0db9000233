"""``routefuse serve`` without a browser: argument handling, the default sample, bind address."""

from __future__ import annotations

import _thread
import socket
import threading
import time
import urllib.request

import pytest

from estimator.errors import RoutefuseError
from inspector.cli import build_parser
from inspector.commands import serve


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_defaults_bind_localhost_and_open_the_long_tunnel_sample():
    args = build_parser().parse_args(["serve"])
    assert args.host == "127.0.0.1" and args.port == 8080 and args.log is None
    if not serve.SAMPLE_LOGS.joinpath("long_tunnel.mcap").exists():
        pytest.skip("sample_logs/long_tunnel.mcap is not generated yet")
    log, route = serve.resolve_inputs(None, None)
    assert log.name == "long_tunnel.mcap" and route.name == "long_tunnel.route.geojson"


def test_route_is_found_beside_the_log_or_the_error_says_what_to_do(tmp_path):
    log = tmp_path / "drive.mcap"
    log.write_bytes(b"x")
    with pytest.raises(RoutefuseError, match="give one with --route"):
        serve.resolve_inputs(str(log), None)
    (tmp_path / "drive.route.geojson").write_text("{}")
    assert serve.resolve_inputs(str(log), None)[1].name == "drive.route.geojson"
    with pytest.raises(RoutefuseError, match="no such file"):
        serve.resolve_inputs(str(tmp_path / "missing.mcap"), None)
    with pytest.raises(RoutefuseError, match="no such file"):
        serve.resolve_inputs(str(log), str(tmp_path / "nope.gpx"))


def test_data_dir_must_be_a_folder(tmp_path):
    with pytest.raises(RoutefuseError, match="not a folder"):
        serve.start(host="127.0.0.1", port=_free_port(), data_dirs=[tmp_path / "absent"])


def test_execute_warns_on_a_public_host_and_prints_the_url(tmp_path, capsys):
    log = tmp_path / "drive.mcap"
    log.write_bytes(b"not a bag")
    (tmp_path / "drive.route.geojson").write_text("{}")
    port = _free_port()
    args = build_parser().parse_args(["serve", str(log), "--host", "0.0.0.0", "--port", str(port)])

    def interrupt_when_served() -> None:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2).read(100)
                break
            except OSError:
                time.sleep(0.2)
        time.sleep(2.0)  # let the (failing) load report
        _thread.interrupt_main()

    threading.Thread(target=interrupt_when_served, daemon=True).start()
    assert serve.execute(args) == 0
    out, err = capsys.readouterr()
    assert f"http://127.0.0.1:{port}" in out
    assert "warning: binding 0.0.0.0" in err
    assert "routefuse: error:" in err and "drive.mcap" in err  # reported; the server stayed up
