"""The inspector's session logic without a browser: the latest-request-wins worker, what it
re-runs, and the outages it injects."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from fake_runs import data_folder, fake_open, fake_run

from estimator.errors import ConfigError, RoutefuseError
from estimator.params import Params, with_values
from inspector.app.view import MAX_NOTE
from inspector.controller import Controller, DataFolders


def _controller(tmp_path: Path, **kw) -> Controller:
    return Controller(
        DataFolders.of(data_folder(tmp_path)), opener=fake_open, runner=fake_run, **kw
    )


def test_open_builds_a_session_and_a_bad_file_keeps_it(tmp_path):
    errors: list[RoutefuseError] = []
    progress: list[float] = []
    c = _controller(tmp_path)
    try:
        c.subscribe(on_error=errors.append, on_progress=lambda f, m: progress.append(f))
        c.open_named("data/drive.mcap", "data/drive.route.geojson")
        assert c.wait_idle(10)
        s = c.session
        assert s is not None and s.log_name == "data/drive.mcap"
        assert s.proposed.method == "proposed" and s.baseline.method == "baseline"
        assert len(s.scene.matches) == 5 and s.metrics[0][0].startswith("max position")
        assert progress[-1] == 1.0 and all(0 <= f <= 1 for f in progress)
        bad = tmp_path / "data" / "bad.mcap"
        bad.write_bytes(b"x")
        c.open_named("data/bad.mcap", "data/drive.route.geojson")
        assert c.wait_idle(10)
        assert c.session is s
        assert len(errors) == 1 and "not a bag" in str(errors[0])
        with pytest.raises(RoutefuseError):
            c.open_named("data/../../etc/passwd", "data/drive.route.geojson")
    finally:
        c.close()


def test_bad_parameter_value_is_refused_before_the_worker(tmp_path):
    c = _controller(tmp_path)
    try:
        with pytest.raises(ConfigError, match="outside"):
            c.set_param("gates.max_residual_m", -1.0)
        with pytest.raises(ConfigError, match="unknown parameter"):
            c.set_param("gates.nope", 1.0)
    finally:
        c.close()


def test_latest_parameter_request_wins(tmp_path):
    calls: list[float] = []
    release = threading.Event()

    def slow_run(inputs, params, method, progress, reuse, **kw):
        calls.append(params.gates.max_residual_m)
        for _ in range(50):
            progress(0.5)  # a superseded run stops here
            if release.is_set():
                break
            time.sleep(0.01)
        return fake_run(inputs, params, method, progress, reuse, **kw)

    c = Controller(DataFolders.of(data_folder(tmp_path)), opener=fake_open, runner=slow_run)
    try:
        release.set()
        c.open_named("data/drive.mcap", "data/drive.route.geojson")
        assert c.wait_idle(10)
        first = c.session
        published: list[float] = []
        c.subscribe(on_session=lambda s: published.append(s.params.gates.max_residual_m))
        release.clear()
        calls.clear()
        for v in np.arange(3.5, 8.0, 0.5):
            c.set_param("gates.max_residual_m", float(v))
            time.sleep(0.02)
        release.set()
        assert c.wait_idle(10)
        s = c.session
        assert s is not None and s is not first
        assert s.params.gates.max_residual_m == 7.5
        # nine requests while runs were slow: superseded runs were abandoned, only the last
        # request (perhaps with one that had finished before the next arrived) was published
        assert len(calls) >= 2
        assert len(published) <= 2 and published[-1] == 7.5
        assert c.params == s.params and not c.busy
    finally:
        c.close()


def test_same_parameters_do_not_rerun(tmp_path):
    runs: list[str] = []

    def counting_run(inputs, params, method, progress, reuse, **kw):
        runs.append(method)
        return fake_run(inputs, params, method, progress, reuse, **kw)

    c = Controller(DataFolders.of(data_folder(tmp_path)), opener=fake_open, runner=counting_run)
    try:
        c.open_named("data/drive.mcap", "data/drive.route.geojson")
        assert c.wait_idle(10)
        n = len(runs)
        c.set_params(c.params)
        c.set_param("gates.max_residual_m", c.params.gates.max_residual_m)
        assert c.wait_idle(10) and len(runs) == n
        c.set_param("gates.max_residual_m", 4.0)
        assert c.wait_idle(10)
        assert c.session.params == with_values(Params(), {"gates.max_residual_m": 4.0})
        c.reset_params()
        assert c.wait_idle(10) and c.session.params == Params()
    finally:
        c.close()


SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"


@pytest.mark.slow
def test_real_sample_loads_and_a_gate_change_reruns_only_what_changed():
    if not (SAMPLES / "long_tunnel.mcap").exists():
        pytest.skip("sample_logs/long_tunnel.mcap is not generated yet")
    errors: list[RoutefuseError] = []
    c = Controller(DataFolders.of(SAMPLES))
    try:
        c.subscribe(on_error=errors.append)
        c.open_named("sample_logs/long_tunnel.mcap", "sample_logs/long_tunnel.route.geojson")
        assert c.wait_idle(300) and not errors
        s = c.session
        assert s.baseline.method == "baseline" and s.proposed.method == "proposed"
        assert s.timeline.n_frames == len(s.proposed.epochs.t) > 1000
        assert len(s.timeline.match_t) == len(s.scene.matches) > 10
        assert s.scene.truth is not None and len(s.scene.gnss_fixes) > 100
        rows = dict((q, (b, p)) for q, b, p in s.metrics)
        assert float(rows["position deviation RMSE [m]"][1]) < float(
            rows["position deviation RMSE [m]"][0]
        )  # the route constraint helps on its own sample
        c.set_param("gates.min_pairs", 500)  # more pairs than any window has
        assert c.wait_idle(300) and not errors
        s2 = c.session
        assert s2.inputs is s.inputs  # the log was not read again
        assert not s2.timeline.match_accepted.any()
        assert s2.timeline.t[0] == s.timeline.t[0]  # same clock: tabs keep their time
    finally:
        c.close()


# -- injected GNSS outages ----------------------------------------------------------------------


class _Log:
    """Just what the controller and the views read of a log without truth or GNSS."""

    duration_s = 100.0
    truth = None

    class gnss:
        t = np.empty(0)


def _open_with_log(log_path, route_path, progress, route_feature=None, topics=None):
    inputs = fake_open(log_path, route_path, progress, route_feature, topics)
    return type(inputs)(log=_Log(), route=inputs.route, frame=inputs.frame)


def _recording_controller(tmp_path: Path, calls: list) -> Controller:
    def recording_run(inputs, params, method, progress, reuse, *, outages):
        calls.append((method, outages, reuse))
        return fake_run(inputs, params, method, progress, reuse, outages=outages)

    return Controller(
        DataFolders.of(data_folder(tmp_path)), opener=_open_with_log, runner=recording_run
    )


def test_changing_the_outages_reruns_both_methods_with_them(tmp_path):
    calls: list = []
    c = _recording_controller(tmp_path, calls)
    try:
        c.open_named("data/drive.mcap", "data/drive.route.geojson")
        assert c.wait_idle(10)
        first = c.session
        assert first.outages == () and c.outages == ()
        assert [(m, o) for m, o, _ in calls] == [("baseline", ()), ("proposed", ())]
        calls.clear()
        c.set_outages([(90.0, 95.0), (20.0, 50.0)])
        assert c.outages == ((20.0, 50.0), (90.0, 95.0))  # at once, before the run
        assert c.wait_idle(10)
        s = c.session
        assert s is not first and s.outages == ((20.0, 50.0), (90.0, 95.0))
        assert s.inputs is first.inputs  # the log was not read again
        assert [(m, o) for m, o, _ in calls] == [
            ("baseline", s.outages),
            ("proposed", s.outages),
        ]
        # runs without these outages are not resumed (a baseline would be taken as it was);
        # the method resumes from this session's baseline (run_methods)
        assert calls[0][2] is None and calls[1][2].method == "baseline"
        calls.clear()
        c.set_outages([(20.0, 50.0), (90.0, 95.0)])  # the same, in another order
        assert c.wait_idle(10) and calls == [] and c.session is s
        c.set_param("gates.max_residual_m", 4.0)  # a parameter change keeps the outages
        assert c.wait_idle(10) and c.session.outages == s.outages
        assert {o for _, o, _ in calls} == {s.outages}
        calls.clear()
        c.set_outages(())
        assert c.wait_idle(10) and c.session.outages == ()
        assert [m for m, _, _ in calls] == ["baseline", "proposed"]
    finally:
        c.close()


def test_invalid_outages_are_refused_and_keep_the_session(tmp_path):
    errors: list[RoutefuseError] = []
    calls: list = []
    c = _recording_controller(tmp_path, calls)
    try:
        c.subscribe(on_error=errors.append)
        c.open(tmp_path / "data/drive.mcap", tmp_path / "data/drive.route.geojson")
        assert c.wait_idle(10)
        c.set_outages([(20.0, 50.0)])
        assert c.wait_idle(10)
        s = c.session
        with pytest.raises(ConfigError, match="END must be after START"):
            c.set_outages([(50.0, 20.0)])
        assert c.outages == s.outages and not c.busy
        calls.clear()
        c.set_outages([(20.0, 50.0), (150.0, 160.0)])  # the log is 100 s long
        assert c.wait_idle(10)
        assert c.session is s and c.outages == ((20.0, 50.0),)
        assert calls == []  # refused before any run
        assert len(errors) == 1
        assert str(errors[0]) == "GNSS outages: 150:160 starts after the log ends (100.0 s)"
    finally:
        c.close()


def test_another_log_clears_the_outages_and_another_route_keeps_them(tmp_path):
    calls: list = []
    c = _recording_controller(tmp_path, calls)
    try:
        c.open_named("data/drive.mcap", "data/drive.route.geojson")
        c.set_outages([(20.0, 50.0)])
        assert c.wait_idle(10) and c.session.outages == ((20.0, 50.0),)
        c.open_named("data/drive.mcap", "data/sub/old.gpx")  # same log, another route
        assert c.wait_idle(10)
        assert c.session.route_name == "data/sub/old.gpx"
        assert c.session.outages == ((20.0, 50.0),)
        c.open_named("data/sub/old.bag", "data/sub/old.gpx")  # times of another log
        assert c.outages == ()
        assert c.wait_idle(10) and c.session.outages == ()
        assert calls[-1][:2] == ("proposed", ())
        c.open(
            tmp_path / "data/drive.mcap", tmp_path / "data/drive.route.geojson", outages=[(5, 9)]
        )
        assert c.wait_idle(10) and c.session.outages == ((5.0, 9.0),)
    finally:
        c.close()


def test_outages_set_before_anything_is_loaded_apply_to_the_first_log(tmp_path):
    calls: list = []
    c = _recording_controller(tmp_path, calls)
    try:
        c.set_outages([(20.0, 50.0)])
        assert c.outages == ((20.0, 50.0),) and c.session is None and not c.busy
        c.open_named("data/drive.mcap", "data/drive.route.geojson")
        assert c.wait_idle(10) and c.session.outages == ((20.0, 50.0),)
        assert {o for _, o, _ in calls} == {((20.0, 50.0),)}
    finally:
        c.close()


def _two_line_folder(tmp_path: Path) -> Path:
    """A data folder with the monaco sample's log, its route, and a route file of two lines."""
    import shutil

    from fake_runs import MONACO_LOG, MONACO_ROUTE, two_line_route

    d = tmp_path / "data"
    d.mkdir()
    shutil.copy(MONACO_LOG, d / "monaco.mcap")
    shutil.copy(MONACO_ROUTE, d / "monaco.route.geojson")
    two_line_route(d / "two.route.geojson")
    return d


@contextlib.contextmanager
def _opened_on_monaco(d: Path) -> Iterator[tuple[Controller, list[RoutefuseError]]]:
    """A controller over ``d`` with the monaco sample open (no error) and the errors it
    reports from then on; closed afterwards."""
    errors: list[RoutefuseError] = []
    c = Controller(DataFolders.of(d), runner=fake_run)
    try:
        c.subscribe(on_error=errors.append)
        c.open_named("data/monaco.mcap", "data/monaco.route.geojson")
        assert c.wait_idle(60) and c.session is not None and not errors
        yield c, errors
    finally:
        c.close()


def test_a_route_file_of_several_lines_opens_the_chosen_line_and_reruns_keep_it(tmp_path):
    """The real opener: a file of two lines opened without a line is refused in one line that
    says where the browser chooses one; the line chosen is carried by every later request."""
    from fake_runs import HOSTILE_LINE

    d = _two_line_folder(tmp_path)
    with _opened_on_monaco(d) as (c, errors):
        first = c.session
        assert first.route_feature is None
        assert c.route_lines("data/two.route.geojson") == (HOSTILE_LINE, "east")
        assert c.route_lines("data/monaco.route.geojson") == ("monaco_tunnel route",)

        c.open_named("data/monaco.mcap", "data/two.route.geojson")
        assert c.wait_idle(60) and c.session is first  # the session before is kept
        assert [str(e) for e in errors] == [
            f"{d / 'two.route.geojson'}: the file has 2 lines (0: {HOSTILE_LINE}, 1: east); "
            "choose one under 'route line' in the Files tab, then press 'open'"
        ]

        c.open_named("data/monaco.mcap", "data/two.route.geojson", route_feature=1)
        assert c.wait_idle(60)
        s = c.session
        assert s is not first and s.route_feature == 1 and c.route_feature == 1
        assert s.inputs.route.name == "east"
        c.set_param("gates.max_residual_m", 2.5)  # a parameter change re-runs on that line
        assert c.wait_idle(60) and c.session is not s
        assert c.session.route_feature == 1 and c.session.inputs is s.inputs
        assert len(errors) == 1


@pytest.mark.parametrize(
    ("feature", "problem"),
    [
        (5, "no line numbered 5; the file has 2 lines"),
        ("nope", "no line feature named or numbered 'nope'; the file has 2 lines"),
    ],
)
def test_an_unknown_route_line_is_one_line_and_keeps_the_session(tmp_path, feature, problem):
    d = _two_line_folder(tmp_path)
    errors: list[RoutefuseError] = []
    c = Controller(DataFolders.of(d), runner=fake_run)
    try:
        c.subscribe(on_error=errors.append)
        c.open_named("data/monaco.mcap", "data/two.route.geojson", route_feature="east")
        assert c.wait_idle(60) and c.session is not None
        kept = c.session
        c.open_named("data/monaco.mcap", "data/two.route.geojson", route_feature=feature)
        assert c.wait_idle(60) and c.session is kept and kept.route_feature == "east"
        assert len(errors) == 1
        text = str(errors[0])
        assert text.startswith(f"{d / 'two.route.geojson'}: {problem}") and "\n" not in text
        # a later parameter change runs on the line loaded, not on the one refused
        c.set_param("gates.max_residual_m", 2.5)
        assert c.wait_idle(60) and c.session.route_feature == "east" and len(errors) == 1
    finally:
        c.close()


def test_a_route_line_that_is_neither_name_nor_index_is_refused_at_once(tmp_path):
    c = _controller(tmp_path)
    try:
        for bad in (object(), 1.5, "x" * 1000):
            with pytest.raises(RoutefuseError, match=r"route line: .* is not a line's name"):
                c.open_named("data/drive.mcap", "data/drive.route.geojson", route_feature=bad)
        assert c.wait_idle(10) and c.session is None
    finally:
        c.close()


def _two_imu_folder(tmp_path: Path) -> Path:
    """A data folder with a log of two IMU topics (and its route) and the monaco sample's log,
    which has one (/imu/data)."""
    import shutil

    from fake_runs import MONACO_LOG, MONACO_ROUTE, two_imu_log

    d = tmp_path / "data"
    two_imu_log(d)
    shutil.copy(MONACO_LOG, d / "monaco.mcap")
    shutil.copy(MONACO_ROUTE, d / "monaco.route.geojson")
    return d


def test_the_server_s_topics_apply_to_every_log_opened_and_reruns_keep_them(tmp_path):
    """``routefuse serve --imu-topic /imu/raw --no-wheel``: the log of two IMU topics opens
    on /imu/raw without its wheel speed, a parameter change re-runs on the same inputs; a log
    without /imu/raw is refused in one line naming it, and the session before is kept."""
    from estimator.io import TopicChoice

    d = _two_imu_folder(tmp_path)
    chosen = TopicChoice(imu="/imu/raw", no_wheel=True)
    errors: list[RoutefuseError] = []
    c = Controller(DataFolders.of(d), runner=fake_run, topics=chosen)
    try:
        c.subscribe(on_error=errors.append)
        assert c.topics == chosen
        c.open_named("data/two_imu.bag", "data/two_imu.route.geojson")
        assert c.wait_idle(60) and not errors
        s = c.session
        assert s is not None and s.topics == chosen and c.topics == chosen
        roles = {t.topic: t.role for t in s.inputs.log.topics}
        assert roles["/imu/raw"] == "imu" and roles["/imu/data"] == ""
        assert s.inputs.log.wheel is None and roles["/wheel/odom"] == ""
        c.set_param("gates.max_residual_m", 2.5)  # a parameter change re-runs on those topics
        assert c.wait_idle(60) and c.session is not s
        assert c.session.topics == chosen and c.session.inputs is s.inputs

        kept = c.session
        c.open_named("data/monaco.mcap", "data/monaco.route.geojson")
        assert c.wait_idle(60) and c.session is kept
        assert len(errors) == 1
        text = str(errors[0])
        assert text.startswith(f"{d / 'monaco.mcap'}: no topic /imu/raw (--imu-topic); topics: ")
        assert "\n" not in text
        c.set_param("gates.max_residual_m", 3.0)  # the session kept still re-runs
        assert c.wait_idle(60) and c.session.inputs is s.inputs and len(errors) == 1
    finally:
        c.close()


def test_several_imu_topics_in_the_browser_say_to_restart_serve_with_the_flag(tmp_path):
    """A log of two IMU topics opened from the Files tab with no topic chosen: one line saying
    where a browser user chooses (the server's command line), the session before kept."""
    d = _two_imu_folder(tmp_path)
    with _opened_on_monaco(d) as (c, errors):
        kept = c.session
        c.open_named("data/two_imu.bag", "data/two_imu.route.geojson")
        assert c.wait_idle(60) and c.session is kept
        assert len(errors) == 1
        text = str(errors[0])
        way_out = "; choose one by restarting 'routefuse serve' with --imu-topic TOPIC (topics: "
        assert text.startswith(
            f"{d / 'two_imu.bag'}: several imu topics: /imu/data, /imu/raw{way_out}"
        )
        assert "\n" not in text and "choose one with --imu-topic" not in text
        # the way out is within what a notification shows (the topic listing may be cut)
        assert text.index(way_out) + len(way_out) <= MAX_NOTE
