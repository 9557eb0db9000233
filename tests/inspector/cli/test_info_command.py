from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimator.io import BagTopics, write_bag
from estimator.log import GnssData, ImuData, WheelData
from inspector.cli.main import main

T0 = 1_650_000_000.0


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(["info", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def _outage_log(path: Path, **kwargs) -> Path:
    """60 s at 100 Hz IMU, 10 Hz GNSS; NO_FIX in [20, 30) s, no messages in [40, 45) s,
    10 m/s north."""
    t = T0 + 0.01 * np.arange(6000)
    imu = ImuData(t, np.zeros((6000, 3)), np.tile([0.0, 0.0, 9.8], (6000, 1)))
    tg = t[::10]
    rel = tg - T0
    keep = ~((rel >= 40.0) & (rel < 45.0))
    tg, rel = tg[keep], rel[keep]
    status = np.where((rel >= 20.0) & (rel < 30.0), -1, 0).astype(np.int8)
    lat = 40.0 + rel * 10.0 / 111_000.0
    gnss = GnssData(
        tg, lat, np.full(len(tg), -3.0), np.full(len(tg), 600.0), status, np.ones((len(tg), 3))
    )
    wheel = WheelData(t[::5], np.full(1200, 10.0))
    write_bag(path, imu=imu, gnss=gnss, wheel=wheel, **kwargs)
    return path


def test_outages_distances_and_rates(tmp_path: Path, capsys) -> None:
    code, out, err = _run(capsys, _outage_log(tmp_path / "drive.mcap"))
    assert code == 0 and err == ""
    assert "start     2022-04-15 05:20:00.000 UTC   span 59.99 s" in out
    assert (
        "outages   2 without a valid fix for more than 1.0 s: 19.9-30.0 s (10.1 s), "
        "39.9-45.0 s (5.1 s)" in out
    )
    assert "GNSS      450 valid of 550 fixes" in out
    assert "599.5 m from wheel-speed integral" in out  # 1200 samples, 0 to 59.95 s
    gnss_m = float(out.split(" m from GNSS fixes")[0].rsplit(maxsplit=1)[-1])
    assert gnss_m == pytest.approx(599.0 - 4.0, abs=0.5)  # smoothing drops 2 fixes per end
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines() if "/msg/" in line}
    assert rows["/imu/data"] == ["sensor_msgs/msg/Imu", "6000", "100.0", "Hz", "imu"]
    assert rows["/wheel/odom"] == ["nav_msgs/msg/Odometry", "1200", "20.0", "Hz", "wheel"]


def test_log_without_any_fix(tmp_path: Path, capsys) -> None:
    path = tmp_path / "dark.mcap"
    t = T0 + 0.1 * np.arange(100)
    nan = np.full(100, np.nan)
    write_bag(
        path,
        imu=ImuData(t, np.zeros((100, 3)), np.tile([0.0, 0.0, 9.81], (100, 1))),
        gnss=GnssData(t, nan, nan, nan, np.full(100, -1, np.int8), np.ones((100, 3))),
        wheel=WheelData(t, np.full(100, 2.0)),
    )
    code, out, _ = _run(capsys, path)
    assert code == 0
    assert "GNSS      0 valid of 100 fixes" in out
    assert "outages   1 without a valid fix for more than 1.0 s: 0.0-9.9 s (9.9 s)" in out
    assert "distance  19.8 m from wheel-speed integral" in out
    assert "warning   GNSS /gnss/fix: no valid fix in the whole log" in out


def test_topic_options_and_unused_topics(tmp_path: Path, capsys) -> None:
    path = _outage_log(
        tmp_path / "drive.bag",
        storage="ros1",
        topics=BagTopics(imu="/vehicle/imu", wheel="/vehicle/odom"),
    )
    code, out, _ = _run(capsys, path, "--imu-topic", "/vehicle/imu")
    assert code == 0 and "/vehicle/imu" in out and "100.0 Hz  imu" in out
    code, _, err = _run(capsys, path, "--imu-topic", "/imu/data")
    assert code == 3
    assert err == (
        f"routefuse: error: {path}: no topic /imu/data (--imu-topic); topics: "
        "/gnss/fix (NavSatFix), /vehicle/imu (Imu), /vehicle/odom (Odometry)\n"
    )


def test_route_summary(tmp_path: Path, capsys) -> None:
    log = _outage_log(tmp_path / "drive.mcap")
    route = tmp_path / "road.geojson"
    # 3 m west of the track (1 deg of longitude is 85.4 km at 40 deg), 100 m past both ends
    west = -3.0 - 3.0 / 85_395.0
    coords = [[west, 40.0 - 0.0009], [west, 40.0063]]
    route.write_text(
        json.dumps(
            {
                "type": "Feature",
                "properties": {"name": "A1"},
                "geometry": {"type": "LineString", "coordinates": coords},
            }
        )
    )
    code, out, _ = _run(capsys, log, "--route", route)
    assert code == 0
    assert f"route     {route}: 'A1', " in out and "2 vertices" in out
    median = float(out.split("positions from the route: median ")[1].split(" m")[0])
    assert median == pytest.approx(3.0, abs=0.01)


def test_route_file_as_log_lists_its_lines(tmp_path: Path, capsys) -> None:
    path = tmp_path / "two.gpx"
    path.write_text(
        '<gpx><rte><name>a</name><rtept lat="1" lon="2"/><rtept lat="1.001" '
        'lon="2"/></rte><trk><trkseg><trkpt lat="1" lon="2"/><trkpt lat="1" '
        'lon="2.001"/></trkseg></trk></gpx>'
    )
    code, out, _ = _run(capsys, path)
    assert code == 0
    assert out.splitlines()[0] == f"route file {path}: 2 lines"
    assert "'track 0': 111.3 m, 2 vertices" in out and "'a': 110.6 m" in out


def _bad_files(tmp_path: Path) -> dict[str, tuple[list[str], str]]:
    good = _outage_log(tmp_path / "good.mcap")
    (tmp_path / "empty.bag").write_bytes(b"")
    (tmp_path / "notes.bag").write_text("this is not a bag\n")
    (tmp_path / "cut.mcap").write_bytes(good.read_bytes()[:20_000])
    write_bag(tmp_path / "noimu.mcap", wheel=WheelData(T0 + np.arange(10.0), np.zeros(10)))
    (tmp_path / "one.geojson").write_text('{"type": "LineString", "coordinates": [[1, 2]]}')
    (tmp_path / "route.shp").write_bytes(b"\x00\x00\x27\x0a")
    return {
        "empty": ([str(tmp_path / "empty.bag")], "empty.bag: file is empty"),
        "text": ([str(tmp_path / "notes.bag")], "notes.bag: not a ROS 1 bag"),
        "truncated": ([str(tmp_path / "cut.mcap")], "cut.mcap: cannot read the bag"),
        "no imu": ([str(tmp_path / "noimu.mcap")], "noimu.mcap: no IMU topic"),
        "short route": (
            [str(good), "--route", str(tmp_path / "one.geojson")],
            "one.geojson: route has 1 point",
        ),
        "route format": (
            [str(good), "--route", str(tmp_path / "route.shp")],
            "route.shp: unknown route format '.shp'",
        ),
        "missing": ([str(tmp_path / "nothing.mcap")], "nothing.mcap: no such file"),
    }


def test_bad_files_exit_3_with_one_line(tmp_path: Path, capsys) -> None:
    for name, (argv, problem) in _bad_files(tmp_path).items():
        code, out, err = _run(capsys, *argv)
        assert code == 3, name
        assert out == "" and err.count("\n") == 1 and err.startswith("routefuse: error: /"), name
        assert problem in err, (name, err)


def test_every_shared_data_file(shared_data: Path, capsys) -> None:
    logs = sorted([*shared_data.rglob("*.bag"), *shared_data.rglob("*.mcap")])
    routes = sorted(shared_data.rglob("*.geojson"))
    assert logs and routes
    for path in [*logs, *routes]:
        code, out, err = _run(capsys, path)
        assert code == 0 and err == "", (path, err)
        assert str(path) in out.splitlines()[0]
    for path in sorted(p for p in shared_data.rglob("*") if p.is_file()):
        if path not in logs and path not in routes:
            code, _, err = _run(capsys, path)
            assert code == 3 and err.count("\n") == 1 and str(path) in err


def test_every_sample_log() -> None:
    sample_logs = Path(__file__).resolve().parents[3] / "sample_logs"
    files = sorted(p for p in sample_logs.glob("*") if p.suffix in (".mcap", ".bag", ".geojson"))
    if not files:
        pytest.skip(f"no sample logs in {sample_logs}")
    for path in files:
        assert main(["info", str(path)]) == 0, path


def test_real_husky_bag(shared_data: Path, capsys) -> None:
    code, out, _ = _run(capsys, shared_data / "robot_localization" / "test1.bag")
    assert code == 0
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines() if "/msg/" in line}
    assert rows["/imu/data"] == ["sensor_msgs/msg/Imu", "11865", "30.0", "Hz", "imu"]
    assert rows["/fix"] == ["sensor_msgs/msg/NavSatFix", "989", "2.5", "Hz", "gnss"]
    assert "358.9 m from wheel-speed integral" in out
    assert "989 valid of 989 fixes" in out and "outages   none" in out


def test_real_car_with_route(shared_data: Path, capsys) -> None:
    d = shared_data / "comma2k19"
    code, out, _ = _run(capsys, d / "i280.mcap", "--route", d / "i280_route.geojson")
    assert code == 0
    assert "1011.3 m from ground truth" in out and "1003.8 m from wheel-speed integral" in out
    assert "1411.3 m, 6 vertices" in out


def test_rate_is_the_streams_own_not_lowered_by_an_outage(tmp_path: Path, capsys) -> None:
    """10 Hz GNSS with 5 s without a message: 10.0 Hz (1 / median interval), not the 9.2 Hz of
    550 fixes over 59.9 s; every rate decoded, so no ``~`` and no note about it."""
    code, out, _ = _run(capsys, _outage_log(tmp_path / "drive.mcap"))
    assert code == 0
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines() if "/msg/" in line}
    assert rows["/gnss/fix"] == ["sensor_msgs/msg/NavSatFix", "550", "10.0", "Hz", "gnss"]
    assert "~" not in out and "median interval" not in out


def test_monaco_gnss_rate_is_the_receivers_5_hz(capsys) -> None:
    """761 fixes at 5 Hz around a 116 s outage in 268 s: 5.0 Hz (count / span gave 2.8); the
    topic the estimator does not decode keeps its ``~`` count / span, explained under the table."""
    log = Path(__file__).resolve().parents[3] / "sample_logs" / "monaco_tunnel.mcap"
    if not log.exists():
        pytest.skip(f"{log} is not generated")
    code, out, _ = _run(capsys, log)
    assert code == 0
    lines = out.splitlines()
    rows = {line.split()[0]: line.split()[1:] for line in lines if "/msg/" in line}
    assert rows["/gnss/fix"][1:] == ["761", "5.0", "Hz", "gnss"]
    assert rows["/ground_truth/odom"][1:] == ["2680", "~10.0", "Hz", "truth_pose"]
    note = lines.index(
        "  rate: 1 / median interval between messages; ~: count / span (a topic routefuse does "
        "not decode)"
    )
    assert "/msg/" in lines[note - 1] and lines[note + 1] == ""


def test_route_that_is_a_folder_or_missing(tmp_path: Path, capsys) -> None:
    log = _outage_log(tmp_path / "drive.mcap")
    code, out, err = _run(capsys, log, "--route", tmp_path)
    assert code == 3 and out == ""
    assert err == f"routefuse: error: {tmp_path}: is a folder, expected a route file\n"
    code, _, err = _run(capsys, tmp_path / "nothing.foo", "--route", tmp_path)
    assert code == 3 and "nothing.foo: no such file or folder" in err  # the log's problem first
