"""``routefuse serve`` without a browser: argument handling, the default sample, bind address."""

from __future__ import annotations

import socket
from types import SimpleNamespace

import pytest

from estimator.errors import RoutefuseError
from inspector.cli import serve
from inspector.cli.main import build_parser
from tests.inspector._ctrl_c import ctrl_c_when_served


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
    # with its trap route: the middle of the tunnel along the parallel bore, refused
    assert log.name == "long_tunnel.mcap"
    assert route.name == "long_tunnel_parallel_bore.route.geojson"
    assert serve.resolve_inputs(str(log), None)[1].name == "long_tunnel.route.geojson"


def test_the_trap_route_gives_the_default_view_refusals_and_keeps_the_estimate():
    """The bundled trap: 1.2 km of the tunnel drawn 25 m over. Its matches are refused and the
    run stays within half a metre of the sample's own route (no wrong road followed)."""
    from estimator.evaluation.metrics import method_metrics
    from estimator.params import Params
    from estimator.pipeline import open_inputs, run_methods

    if not serve.SAMPLE_LOGS.joinpath("long_tunnel.mcap").exists():
        pytest.skip("sample_logs/long_tunnel.mcap is not generated yet")
    log, trap = serve.resolve_inputs(None, None)
    rmse = {}
    for route in (trap, log.with_name("long_tunnel.route.geojson")):
        inputs = open_inputs(log, route)
        run = run_methods(inputs, Params(), methods=("proposed",))["proposed"]
        truth = method_metrics(run, inputs.route, inputs.log).truth
        rmse[route.name] = truth.rmse_h_err_m
        if route == trap:
            refused = [m for m in run.matches if not m.accepted]
            assert len(refused) >= 20 and len(refused) < len(run.matches) / 2
    assert rmse[trap.name] < rmse["long_tunnel.route.geojson"] + 0.5


def test_route_is_found_beside_the_log_or_the_error_says_what_to_do(tmp_path):
    log = tmp_path / "drive.mcap"
    log.write_bytes(b"\x89MCAP0\r\n")  # an MCAP file's first bytes: a log by its shape
    with pytest.raises(RoutefuseError, match="give one with --route"):
        serve.resolve_inputs(str(log), None)
    (tmp_path / "drive.route.geojson").write_text("{}")
    assert serve.resolve_inputs(str(log), None)[1].name == "drive.route.geojson"
    with pytest.raises(RoutefuseError, match="no such file"):
        serve.resolve_inputs(str(tmp_path / "missing.mcap"), None)
    with pytest.raises(RoutefuseError, match="no such file"):
        serve.resolve_inputs(str(log), str(tmp_path / "nope.gpx"))
    with pytest.raises(RoutefuseError, match="is a folder, expected a route file"):
        serve.resolve_inputs(str(log), str(tmp_path))


def test_without_route_beside_a_bad_log_is_reported_as_such(tmp_path):
    """The log's own problem, not that it has no route; with a route beside it, a bad log is
    the inspector's to report (the server stays up, see below)."""
    log = tmp_path / "drive.foo"
    log.write_bytes(b"x")
    with pytest.raises(RoutefuseError, match=r"drive\.foo: unknown log format '\.foo'"):
        serve.resolve_inputs(str(log), None)


def test_data_dir_must_be_a_folder(tmp_path):
    with pytest.raises(RoutefuseError, match="not a folder"):
        serve.start(host="127.0.0.1", port=_free_port(), data_dirs=[tmp_path / "absent"])


def test_execute_warns_on_a_public_host_and_prints_the_url(tmp_path, capsys):
    log = tmp_path / "drive.mcap"
    log.write_bytes(b"not a bag")
    (tmp_path / "drive.route.geojson").write_text("{}")
    port = _free_port()
    args = build_parser().parse_args(["serve", str(log), "--host", "0.0.0.0", "--port", str(port)])

    with ctrl_c_when_served(port):
        code = serve.execute(args)
    assert code == 0
    out, err = capsys.readouterr()
    assert f"http://127.0.0.1:{port}" in out
    assert "warning: binding 0.0.0.0" in err
    assert "routefuse: error:" in err and "drive.mcap" in err  # reported; the server stayed up


def test_a_bad_outage_fails_like_export_before_the_server_starts(tmp_path, capsys, monkeypatch):
    from inspector.cli.main import main

    started: list = []
    monkeypatch.setattr(serve, "start", lambda **kw: started.append(kw))
    for bad in ("60:30", "abc", "30-60"):
        assert main(["serve", "--outage", "10:20", "--outage", bad]) == 3
        serve_err = capsys.readouterr().err
        out = str(tmp_path / "out")
        assert (
            main(["export", "x.mcap", "--route", "r.geojson", "--out", out, "--outage", bad]) == 3
        )
        export_err = capsys.readouterr().err
        assert serve_err == export_err  # the same parser, the same one line
        assert serve_err.startswith("routefuse: error: --outage: ")
        assert serve_err.count("\n") == 1 and "Traceback" not in serve_err
    assert started == []


def test_outages_reach_the_server_and_the_status_line(tmp_path, capsys, monkeypatch):
    log = tmp_path / "drive.mcap"
    log.write_bytes(b"x")
    (tmp_path / "drive.route.geojson").write_text("{}")
    opened: list = []
    closed: list = []
    controller = SimpleNamespace(subscribe=lambda **_: None, close=lambda: closed.append("ctl"))
    server = SimpleNamespace(get_port=lambda: 1, stop=lambda: closed.append("server"))
    app = SimpleNamespace(close=lambda: closed.append("app"))

    def fake_start(**kw):
        return server, controller, app

    def fake_open_first(ctl, log_path, route_path, outages, *, route_feature=None):
        opened.append((ctl, log_path, outages))
        raise RoutefuseError(None, "stop here")

    monkeypatch.setattr(serve, "start", fake_start)
    monkeypatch.setattr(serve, "open_first", fake_open_first)
    args = build_parser().parse_args(
        ["serve", str(log), "--outage", "90:120", "--outage", "30:60.5"]
    )
    with pytest.raises(RoutefuseError, match="stop here"):
        serve.execute(args)
    assert opened == [(controller, log.resolve(), ((90.0, 120.0), (30.0, 60.5)))]
    assert "GNSS outages 30:60.5, 90:120 s" in capsys.readouterr().out
    assert closed == ["app", "ctl", "server"]  # a failure at the first load closes the server


SAMPLE = serve.SAMPLE_LOGS / "long_tunnel.mcap"


@pytest.mark.slow
def test_serve_injects_the_outages_into_the_first_session_only():
    """The long_tunnel sample has open sky for its first 100 s: an outage there brings match
    attempts where the natural log has none; the outages do not follow to another log."""
    if not SAMPLE.exists():
        pytest.skip("sample_logs/long_tunnel.mcap is not generated yet")
    from inspector.app import status_markdown

    log, route = serve.resolve_inputs(None, None)
    server, controller, app = serve.start(
        host="127.0.0.1",
        port=_free_port(),
        data_dirs=[],
        log=log,
        route=route,
        outages=((20.0, 80.0),),
    )
    try:
        assert controller.wait_idle(300)
        s = controller.session
        assert s is not None and s.outages == ((20.0, 80.0),)
        t = s.timeline.match_t
        inside = t[(t >= 20.0) & (t <= 80.0)]
        assert len(inside) > 0  # attempts in what was open sky
        a, b = s.proposed.degraded_intervals[0]
        assert (a - s.proposed.t0, b - s.proposed.t0) == pytest.approx((20.0, 80.0), abs=0.5)
        assert s.baseline.degraded_intervals == s.proposed.degraded_intervals
        assert "GNSS removed 20:80 s" in status_markdown(s)
        controller.open_named(
            "sample_logs/multi_tunnel.mcap", "sample_logs/multi_tunnel.route.geojson"
        )
        assert controller.outages == ()
    finally:
        app.close()
        controller.close()
        server.stop()


def test_terminal_progress_is_a_line_per_stage_and_quarter(capsys):
    from inspector.cli.serve import TerminalProgress

    progress = TerminalProgress()
    for k in range(101):
        progress(k / 200, "loading drive.mcap")
    for k in range(51):
        progress(0.5 + k / 100, "baseline")
    lines = capsys.readouterr().out.splitlines()
    assert lines == [
        "  loading drive.mcap (0 %)",
        "  loading drive.mcap (25 %)",
        "  loading drive.mcap (50 %)",
        "  baseline (50 %)",
        "  baseline (75 %)",
    ]


def _route_feature_action(command: str):
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command" or a.choices)
    return next(a for a in sub.choices[command]._actions if a.dest == "route_feature")


def test_serve_has_run_s_route_feature_option():
    """One declaration (options.add_route_feature_option) for every command that reads one."""
    actions = [_route_feature_action(c) for c in ("serve", "run", "export", "info")]
    assert {(a.option_strings[0], a.metavar, a.help) for a in actions} == {
        (
            "--route-feature",
            "NAME_OR_INDEX",
            "which line of a route file that holds several (its name, or its index from 0)",
        )
    }
    args = build_parser().parse_args(["serve", "x.mcap", "--route-feature", "east"])
    assert args.route_feature == "east"


def test_the_route_line_is_checked_before_the_server_starts(tmp_path, capsys, monkeypatch):
    """As ``run`` checks it: several lines and no --route-feature, or one naming none, is one
    line saying to give --route-feature, and no server starts; a name becomes its index."""
    from fake_runs import MONACO_LOG, two_line_route

    from inspector.cli.main import main

    route = two_line_route(tmp_path / "two.route.geojson")
    assert serve.resolve_route_line(route, "east") == 1
    assert serve.resolve_route_line(route, "0") == 0
    assert serve.resolve_route_line(route.with_name("monaco.geojson"), None) is None  # missing
    started: list = []
    monkeypatch.setattr(serve, "start", lambda **kw: started.append(kw))
    log = str(MONACO_LOG)
    assert main(["serve", log, "--route", str(route)]) == 3
    err = capsys.readouterr().err
    assert err == (
        f"routefuse: error: {route}: the file has 2 lines (0: <img src=x onerror=alert(1)>, "
        "1: east); choose one with --route-feature NAME_OR_INDEX\n"
    )
    assert main(["serve", log, "--route", str(route), "--route-feature", "west"]) == 3
    err = capsys.readouterr().err
    assert err.startswith(f"routefuse: error: {route}: no line feature named or numbered 'west'")
    assert err.count("\n") == 1
    assert started == []


def test_the_route_line_reaches_the_first_open(tmp_path, capsys, monkeypatch):
    from fake_runs import MONACO_LOG, two_line_route

    route = two_line_route(tmp_path / "two.route.geojson")
    opened: list = []
    controller = SimpleNamespace(subscribe=lambda **_: None, close=lambda: None)
    server = SimpleNamespace(get_port=lambda: 1, stop=lambda: None)
    app = SimpleNamespace(close=lambda: None)
    monkeypatch.setattr(serve, "start", lambda **kw: (server, controller, app))

    def fake_open_first(ctl, log_path, route_path, outages, *, route_feature=None):
        opened.append((route_path, route_feature))
        raise RoutefuseError(None, "stop here")

    monkeypatch.setattr(serve, "open_first", fake_open_first)
    args = build_parser().parse_args(
        ["serve", str(MONACO_LOG), "--route", str(route), "--route-feature", "east"]
    )
    with pytest.raises(RoutefuseError, match="stop here"):
        serve.execute(args)
    assert opened == [(route.resolve(), 1)]
    assert f"with route {route.name} (line 1) ..." in capsys.readouterr().out


TOPIC_DESTS = ("imu_topic", "gnss_topic", "wheel_topic", "truth_topic", "no_wheel")


def _actions(command: str) -> dict[str, tuple]:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command" or a.choices)
    return {
        a.dest: (tuple(a.option_strings), a.metavar, a.help, a.default)
        for a in sub.choices[command]._actions
        if a.dest in TOPIC_DESTS
    }


def test_serve_has_run_s_topic_options():
    """One declaration (options.add_topic_options) for run, export, info and serve."""
    serve_actions = _actions("serve")
    assert set(serve_actions) == set(TOPIC_DESTS)
    for command in ("run", "export", "info"):
        assert _actions(command) == serve_actions
    args = build_parser().parse_args(["serve", "x.bag", "--imu-topic", "/imu/raw", "--no-wheel"])
    from estimator.io import TopicChoice

    assert TopicChoice.from_args(args) == TopicChoice(imu="/imu/raw", no_wheel=True)


def test_the_topics_are_checked_before_the_server_starts(tmp_path, capsys, monkeypatch):
    """As ``run`` checks them: a log of two IMU topics and no --imu-topic, a topic the log
    lacks, or --wheel-topic with --no-wheel is one line naming the flag, exit 3, and no server
    starts."""
    from fake_runs import two_imu_log

    from inspector.cli.main import main

    log, _ = two_imu_log(tmp_path / "data")
    started: list = []
    monkeypatch.setattr(serve, "start", lambda **kw: started.append(kw))
    assert main(["serve", str(log)]) == 3
    err = capsys.readouterr().err
    assert err.startswith(
        f"routefuse: error: {log}: several imu topics: /imu/data, /imu/raw; choose one with "
        "--imu-topic TOPIC (topics: /gnss/fix (NavSatFix), "
    )
    assert err.count("\n") == 1
    assert main(["serve", str(log), "--imu-topic", "/imu/nope"]) == 3
    err = capsys.readouterr().err
    assert err.startswith(f"routefuse: error: {log}: no topic /imu/nope (--imu-topic); topics: ")
    assert err.count("\n") == 1
    args = ["serve", str(log), "--imu-topic", "/imu/raw", "--wheel-topic", "/wheel/odom"]
    assert main([*args, "--no-wheel"]) == 3
    assert capsys.readouterr().err == (
        f"routefuse: error: {log}: --wheel-topic /wheel/odom and --no-wheel contradict each other\n"
    )
    assert started == []


def test_the_topics_reach_the_controller_and_the_status_line(tmp_path, capsys, monkeypatch):
    from fake_runs import two_imu_log

    from estimator.io import TopicChoice

    log, _ = two_imu_log(tmp_path / "data")
    started: list = []
    controller = SimpleNamespace(subscribe=lambda **_: None, close=lambda: None)
    server = SimpleNamespace(get_port=lambda: 1, stop=lambda: None)
    app = SimpleNamespace(close=lambda: None)

    def fake_start(**kw):
        started.append(kw)
        return server, controller, app

    def fake_open_first(ctl, log_path, route_path, outages, *, route_feature=None):
        raise RoutefuseError(None, "stop here")

    monkeypatch.setattr(serve, "start", fake_start)
    monkeypatch.setattr(serve, "open_first", fake_open_first)
    args = build_parser().parse_args(["serve", str(log), "--imu-topic", "/imu/raw", "--no-wheel"])
    with pytest.raises(RoutefuseError, match="stop here"):
        serve.execute(args)
    assert [kw["topics"] for kw in started] == [TopicChoice(imu="/imu/raw", no_wheel=True)]
    out = capsys.readouterr().out
    assert "loading two_imu.bag (--imu-topic /imu/raw, --no-wheel) with route" in out
