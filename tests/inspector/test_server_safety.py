"""Server safety checks of issue 8 that the other tests leave open: without ``--host`` the
listening socket is bound to the loopback address only (not just the argument's default), with
no warning; an uploaded file is readable by its owner only. (Path traversal through ``..`` and
symlinks, the upload size limit and the private upload folder are tested in test_controller.py
and tests/e2e/test_inspector.py; the warning for a public --host in test_serve.py.)"""

from __future__ import annotations

import socket
import stat
from pathlib import Path

from inspector.cli import serve
from inspector.cli.main import build_parser
from inspector.controller import UploadFolder
from tests.inspector._ctrl_c import ctrl_c_when_served


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _listening_addresses(port: int) -> set[str]:
    """Local addresses of the TCP sockets listening on ``port`` (from /proc/net/tcp{,6})."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, _, st = line.split()[1:4]
            addr, p = local.split(":")
            if int(p, 16) == port and st == "0A":  # LISTEN
                if len(addr) == 8:
                    found.add(socket.inet_ntop(socket.AF_INET, bytes.fromhex(addr)[::-1]))
                else:
                    raw = bytes.fromhex(addr)
                    raw = b"".join(raw[i : i + 4][::-1] for i in range(0, 16, 4))
                    found.add(socket.inet_ntop(socket.AF_INET6, raw))
    return found


def test_without_host_the_server_listens_on_loopback_only_and_does_not_warn(tmp_path, capsys):
    log = tmp_path / "drive.mcap"
    log.write_bytes(b"not a bag")
    (tmp_path / "drive.route.geojson").write_text("{}")
    port = _free_port()
    args = build_parser().parse_args(["serve", str(log), "--port", str(port)])
    seen: dict[str, set[str]] = {}

    def look() -> None:
        seen["addresses"] = _listening_addresses(port)

    with ctrl_c_when_served(port, then=look, settle_s=1.0):
        code = serve.execute(args)
    assert code == 0
    _, err = capsys.readouterr()
    assert "warning: binding" not in err
    assert f"routefuse: error: {log}" in err, "the failed first load was not reported"
    assert seen["addresses"], "the server was not listening"
    assert seen["addresses"] <= {"127.0.0.1", "::1"}, seen["addresses"]


def test_an_uploaded_file_is_readable_by_its_owner_only():
    up = UploadFolder(max_bytes=1000)
    try:
        path = up.save("drive.mcap", b"abc")
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
        assert path.parent == up.path and stat.S_IMODE(up.path.stat().st_mode) == 0o700
        again = up.save("drive.mcap", b"def")  # the same name never overwrites an upload
        assert again != path and path.read_bytes() == b"abc"
    finally:
        up.close()


def test_the_inspector_refuses_websockets_from_other_origins(tmp_path):
    """Cross-site WebSocket hijacking (issue 16): a page of another site cannot connect to the
    inspector the user runs; its own page, its loopback twins and --allow-origin can."""
    import websockets.exceptions
    from websockets.sync.client import connect

    port = _free_port()
    server, controller, app = serve.start(
        host="127.0.0.1",
        port=port,
        data_dirs=[tmp_path],
        allow_origins=["http://dashboard.lan:3000"],
    )

    def status(origin: str) -> int:
        try:
            with connect(f"ws://127.0.0.1:{port}", origin=origin, open_timeout=5):
                return 101
        except websockets.exceptions.InvalidStatus as exc:
            return exc.response.status_code

    try:
        assert status("http://attacker.example") == 403
        assert status(f"http://localhost:{port + 1}") == 403
        assert status(f"http://127.0.0.1:{port}") == 101
        assert status(f"http://localhost:{port}") == 101
        assert status("http://dashboard.lan:3000") == 101
    finally:
        app.close()
        controller.close()
        server.stop()


def test_a_malformed_allow_origin_is_one_line_exit_3(capsys):
    from inspector.cli.main import main

    assert main(["serve", "--allow-origin", "dashboard.lan", "--port", str(_free_port())]) == 3
    err = capsys.readouterr().err.strip()
    assert err.startswith("routefuse: error: --allow-origin:") and "\n" not in err
