from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from estimator.io import BagTopics, StaticTransform, write_bag
from estimator.log import GnssData, ImuData, TruthData, WheelData

T0 = 1_700_000_000.0


def _streams(n: int = 200):
    rng = np.random.default_rng(1)
    t = T0 + 0.01 * np.arange(n)
    imu = ImuData(t, rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) + np.array([0, 0, 9.8]))
    m = n // 10
    status = np.zeros(m, np.int8)
    status[3] = -1
    lat = 37.0 + 1e-5 * np.arange(m)
    gnss = GnssData(
        t[::10], lat, np.full(m, -122.0), np.full(m, 12.0), status, np.tile([1.0, 2.0, 9.0], (m, 1))
    )
    wheel = WheelData(t[::4], np.linspace(0.0, 5.0, len(t[::4])))
    truth = TruthData(
        t[::5],
        np.full(n // 5, 37.0),
        np.full(n // 5, -122.0),
        np.zeros(n // 5),
        np.linspace(-3.0, 3.0, n // 5),
    )
    return imu, gnss, wheel, truth


def _read(path: Path) -> dict[str, list]:
    out: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for conn, t_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t_ns, reader.deserialize(raw, conn.msgtype)))
    return out


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


@pytest.mark.parametrize("storage", ["mcap", "sqlite3", "ros1"])
def test_every_field_reads_back(tmp_path: Path, storage) -> None:
    imu, gnss, wheel, truth = _streams()
    path = tmp_path / {"mcap": "a.mcap", "sqlite3": "folder", "ros1": "a.bag"}[storage]
    counts = write_bag(path, imu=imu, gnss=gnss, wheel=wheel, truth=truth, storage=storage)
    got = _read(path)
    assert counts == {k: len(v) for k, v in got.items()}
    msgs = [m for _, m in got["/imu/data"]]
    np.testing.assert_allclose([_stamp(m) for m in msgs], imu.t, atol=1e-6, rtol=0)
    gyro = [[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for m in msgs]
    acc = [
        [m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for m in msgs
    ]
    np.testing.assert_array_equal(gyro, imu.gyro)
    np.testing.assert_array_equal(acc, imu.accel)
    fixes = [m for _, m in got["/gnss/fix"]]
    assert [f.status.status for f in fixes] == gnss.status.tolist()
    assert np.isnan(fixes[3].latitude) and fixes[3].position_covariance_type == 0
    np.testing.assert_array_equal(
        [f.latitude for f in fixes if f.status.status >= 0], gnss.lat[gnss.status >= 0]
    )
    np.testing.assert_array_equal(fixes[0].position_covariance[[0, 4, 8]], [1.0, 2.0, 9.0])
    assert fixes[0].position_covariance_type == 2
    speeds = [m.twist.twist.linear.x for _, m in got["/wheel/odom"]]
    np.testing.assert_array_equal(speeds, wheel.speed)
    q = [m.pose.pose.orientation for _, m in got["/ground_truth/odom"]]
    yaw = [2 * np.arctan2(o.z, o.w) for o in q]
    np.testing.assert_allclose(np.angle(np.exp(1j * np.array(yaw))), truth.heading, atol=1e-12)
    assert len(got["/ground_truth/fix"]) == len(truth.t)
    receive = [t for t, _ in got["/imu/data"]]
    np.testing.assert_allclose(np.array(receive) * 1e-9, imu.t, atol=1e-6, rtol=0)


def test_messages_are_in_time_order_and_twist_and_tf_static(tmp_path: Path) -> None:
    imu, _, wheel, _ = _streams()
    path = tmp_path / "b.bag"
    topics = BagTopics(imu="/sensors/imu", wheel="/vehicle/speed")
    tf = StaticTransform("base_link", "imu_link", (0.0, 0.0, np.sin(0.25), np.cos(0.25)))
    write_bag(
        path,
        imu=imu,
        wheel=wheel,
        storage="ros1",
        topics=topics,
        wheel_type="twist",
        imu_frame="imu_link",
        static_transforms=[tf],
    )
    with AnyReader([path]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        times = [t for _, t, _ in reader.messages()]
    assert types == {
        "/sensors/imu": "sensor_msgs/msg/Imu",
        "/vehicle/speed": "geometry_msgs/msg/TwistStamped",
        "/tf_static": "tf2_msgs/msg/TFMessage",
    }
    assert times == sorted(times)
    got = _read(path)
    assert got["/sensors/imu"][0][1].header.frame_id == "imu_link"
    np.testing.assert_array_equal([m.twist.linear.x for _, m in got["/vehicle/speed"]], wheel.speed)
    ((_, tfm),) = got["/tf_static"]
    assert tfm.transforms[0].child_frame_id == "imu_link"
    assert tfm.transforms[0].transform.rotation.z == pytest.approx(np.sin(0.25))


def test_mcap_output_is_deterministic_and_bare(tmp_path: Path) -> None:
    imu, gnss, wheel, truth = _streams()
    (tmp_path / "1").mkdir()
    (tmp_path / "2").mkdir()
    a, b = tmp_path / "1" / "a.mcap", tmp_path / "2" / "a.mcap"
    write_bag(a, imu=imu, gnss=gnss, wheel=wheel, truth=truth)
    write_bag(b, imu=imu, gnss=gnss, wheel=wheel, truth=truth)
    assert a.is_file() and a.read_bytes() == b.read_bytes()
    assert [p.name for p in a.parent.iterdir()] == ["a.mcap"]


def test_refuses_to_overwrite_and_bad_times(tmp_path: Path) -> None:
    imu, *_ = _streams()
    path = tmp_path / "a.mcap"
    path.write_bytes(b"")
    with pytest.raises(FileExistsError):
        write_bag(path, imu=imu)
    bad = ImuData(np.array([T0, np.nan]), np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="finite"):
        write_bag(tmp_path / "c.mcap", imu=bad)
