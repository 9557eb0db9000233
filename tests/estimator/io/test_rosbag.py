from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from estimator.errors import LogError
from estimator.io import BagTopics, StaticTransform, TopicChoice, load_log, write_bag
from estimator.io.rosbag import MAX_METADATA_BYTES
from estimator.log import GnssData, ImuData, TruthData, WheelData

T0 = 1_700_000_000.0


def _streams(n: int = 400):
    rng = np.random.default_rng(7)
    t = T0 + 0.01 * np.arange(n)
    imu = ImuData(t, rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) + np.array([0.0, 0.0, 9.81]))
    m = n // 10
    status = np.ones(m, np.int8)
    status[5:8] = -1
    cov = np.tile([1.0, 4.0, 9.0], (m, 1))
    cov[2] = np.nan
    gnss = GnssData(
        t[::10], 48.0 + 1e-5 * np.arange(m), np.full(m, 11.0), np.full(m, 500.0), status, cov
    )
    wheel = WheelData(t[::4], np.linspace(0.0, 3.0, n // 4))
    k = n // 5
    truth = TruthData(
        t[::5], np.full(k, 48.0), np.full(k, 11.0), np.full(k, 499.0), np.linspace(-3.0, 3.0, k)
    )
    return imu, gnss, wheel, truth


NAMES = {"mcap": "log.mcap", "mcap-folder": "mcapbag", "sqlite3": "sqlbag", "ros1": "log.bag"}


@pytest.mark.parametrize("storage", list(NAMES))
def test_round_trip_of_every_storage_kind(tmp_path: Path, storage) -> None:
    imu, gnss, wheel, truth = _streams()
    path = tmp_path / NAMES[storage]
    write_bag(path, imu=imu, gnss=gnss, wheel=wheel, truth=truth, storage=storage)
    log = load_log(path, cache_dir=tmp_path / "cache")
    np.testing.assert_allclose(log.imu.t, imu.t, atol=1e-6, rtol=0)
    np.testing.assert_array_equal(log.imu.gyro, imu.gyro)
    np.testing.assert_array_equal(log.imu.accel, imu.accel)
    np.testing.assert_array_equal(log.gnss.status, gnss.status)
    np.testing.assert_array_equal(log.gnss.valid, gnss.status >= 0)
    ok = gnss.status >= 0
    np.testing.assert_array_equal(log.gnss.lat[ok], gnss.lat[ok])
    assert np.all(np.isnan(log.gnss.lat[~ok]))
    np.testing.assert_array_equal(log.gnss.cov_enu[0], [1.0, 4.0, 9.0])
    assert np.all(np.isnan(log.gnss.cov_enu[2])) and np.all(np.isnan(log.gnss.cov_enu[~ok]))
    assert log.wheel is not None and log.truth is not None
    np.testing.assert_array_equal(log.wheel.speed, wheel.speed)
    np.testing.assert_allclose(log.truth.heading, truth.heading, atol=1e-12)
    np.testing.assert_array_equal(log.truth.alt, truth.alt)
    roles = {t.topic: t.role for t in log.topics}
    assert roles == {
        "/imu/data": "imu",
        "/gnss/fix": "gnss",
        "/wheel/odom": "wheel",
        "/ground_truth/fix": "truth",
        "/ground_truth/odom": "truth_pose",
    }
    assert {t.topic: t.count for t in log.topics}["/imu/data"] == len(imu.t)
    assert log.warnings == ()


def test_second_load_comes_from_the_cache(tmp_path: Path, monkeypatch) -> None:
    imu, gnss, wheel, truth = _streams()
    bag_dir = tmp_path / "bags"
    bag_dir.mkdir()
    path = bag_dir / "log.mcap"
    write_bag(path, imu=imu, gnss=gnss, wheel=wheel, truth=truth)
    cache = tmp_path / "cache"
    first = load_log(path, cache_dir=cache)
    assert len(list(cache.glob("log-*.npz"))) == 1
    assert [p.name for p in bag_dir.iterdir()] == ["log.mcap"]

    def no_reading(*args, **kwargs):
        raise AssertionError("the bag was read again")

    monkeypatch.setattr("rosbags.highlevel.AnyReader", no_reading)
    fractions: list[float] = []
    second = load_log(path, cache_dir=cache, progress=fractions.append)
    assert fractions == [1.0]
    assert second.topics == first.topics and second.warnings == first.warnings
    for part in ("imu", "gnss", "wheel", "truth"):
        a, b = getattr(first, part), getattr(second, part)
        for name in a.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert second.gnss.status.dtype == np.int8
    with pytest.raises(LogError, match="read again"):
        load_log(path, cache_dir=cache, topics=TopicChoice(truth="/ground_truth/fix"))


def test_cache_dir_follows_the_environment(tmp_path: Path, monkeypatch) -> None:
    imu, gnss, *_ = _streams()
    path = tmp_path / "log.mcap"
    write_bag(path, imu=imu, gnss=gnss)
    monkeypatch.setenv("ROUTEFUSE_CACHE_DIR", str(tmp_path / "envcache"))
    load_log(path)
    assert len(list((tmp_path / "envcache").glob("log-*.npz"))) == 1


def test_progress_reaches_one(tmp_path: Path) -> None:
    imu, gnss, *_ = _streams(n=5000)
    path = tmp_path / "log.mcap"
    write_bag(path, imu=imu, gnss=gnss)
    fractions: list[float] = []
    load_log(path, cache_dir=tmp_path / "c", progress=fractions.append)
    assert len(fractions) >= 3 and fractions[-1] == 1.0
    assert fractions == sorted(fractions) and 0 < fractions[0] < 1


def test_topics_are_found_by_type_and_chosen_by_name(tmp_path: Path) -> None:
    imu, gnss, wheel, _ = _streams()
    a, b = tmp_path / "a.bag", tmp_path / "b.bag"
    write_bag(a, imu=imu, gnss=gnss, storage="ros1")
    write_bag(
        b,
        imu=imu,
        wheel=wheel,
        gnss=gnss,
        storage="ros1",
        topics=BagTopics(imu="/imu/raw", gnss="/gps/fix", wheel="/vehicle/twist"),
        wheel_type="twist",
    )
    merged = tmp_path / "merged.bag"
    _merge([a, b], merged)
    with pytest.raises(LogError) as err:
        load_log(merged, cache_dir=tmp_path / "c")
    msg = str(err.value)
    assert msg.startswith(str(merged)) and "\n" not in msg
    assert "several imu topics: /imu/data, /imu/raw" in msg and "--imu-topic" in msg
    log = load_log(
        merged, cache_dir=tmp_path / "c", topics=TopicChoice(imu="/imu/raw", gnss="/gps/fix")
    )
    roles = {t.topic: t.role for t in log.topics}
    assert roles == {
        "/imu/data": "",
        "/imu/raw": "imu",
        "/gnss/fix": "",
        "/gps/fix": "gnss",
        "/vehicle/twist": "wheel",
    }
    assert log.wheel is not None
    np.testing.assert_array_equal(log.wheel.speed, wheel.speed)
    # a topic chosen for one role is no candidate for another
    log = load_log(
        merged, cache_dir=tmp_path / "c", topics=TopicChoice(imu="/imu/raw", truth="/gnss/fix")
    )
    assert {t.topic: t.role for t in log.topics}["/gps/fix"] == "gnss"
    assert log.truth is not None and len(log.truth.t) == len(gnss.t)
    with pytest.raises(LogError, match=r"no topic /nope \(--imu-topic\); topics: /gnss/fix"):
        load_log(merged, cache_dir=tmp_path / "c", topics=TopicChoice(imu="/nope"))
    with pytest.raises(LogError, match="--gnss-topic /imu/raw is a sensor_msgs/msg/Imu"):
        load_log(
            merged, cache_dir=tmp_path / "c", topics=TopicChoice(imu="/imu/raw", gnss="/imu/raw")
        )


def _merge(sources: list[Path], out: Path) -> None:
    from rosbags.rosbag1 import Writer as Writer1

    ts = get_typestore(Stores.ROS1_NOETIC)
    msgs = []
    with Writer1(out) as writer:
        conns = {}
        for src in sources:
            with AnyReader([src]) as reader:
                for c in reader.connections:
                    if c.topic not in conns:
                        conns[c.topic] = writer.add_connection(c.topic, c.msgtype, typestore=ts)
                msgs += [(t, c.topic, raw) for c, t, raw in reader.messages()]
        for t, topic, raw in sorted(msgs, key=lambda m: (m[0], m[1])):
            if conns[topic].topic == topic:
                writer.write(conns[topic], t, raw)


def test_missing_imu_or_gnss_topic_lists_what_the_bag_has(tmp_path: Path) -> None:
    imu, gnss, wheel, _ = _streams()
    no_imu, no_gnss = tmp_path / "no_imu.mcap", tmp_path / "no_gnss.mcap"
    write_bag(no_imu, gnss=gnss, wheel=wheel)
    write_bag(no_gnss, imu=imu)
    with pytest.raises(LogError) as err:
        load_log(no_imu, cache_dir=tmp_path / "c")
    assert str(err.value) == (
        f"{no_imu}: no IMU topic (Imu); topics: /gnss/fix (NavSatFix), /wheel/odom (Odometry)"
    )
    with pytest.raises(LogError, match=r"no GNSS topic .*/imu/data"):
        load_log(no_gnss, cache_dir=tmp_path / "c")


def test_too_few_imu_samples(tmp_path: Path) -> None:
    imu, gnss, *_ = _streams()
    short = ImuData(imu.t[:3], imu.gyro[:3], imu.accel[:3])
    path = tmp_path / "short.mcap"
    write_bag(path, imu=short, gnss=gnss)
    with pytest.raises(LogError, match="too few IMU samples on /imu/data: 3"):
        load_log(path, cache_dir=tmp_path / "c")


def test_repairs_are_applied_and_reported(tmp_path: Path) -> None:
    imu, gnss, wheel, _ = _streams()
    gyro = imu.gyro.copy()
    gyro[10, 1] = np.nan
    t = imu.t.copy()
    t[21] = t[20]
    bad_imu = ImuData(t, gyro, imu.accel)
    wheel_speed = wheel.speed.copy()
    wheel_speed[4] = np.inf
    path = tmp_path / "bad.mcap"
    write_bag(path, imu=bad_imu, gnss=gnss, wheel=WheelData(wheel.t, wheel_speed))
    log = load_log(path, cache_dir=tmp_path / "c")
    assert len(log.imu.t) == len(t) - 2
    assert np.all(np.diff(log.imu.t) > 0) and np.all(np.isfinite(log.imu.gyro))
    assert log.wheel is not None and len(log.wheel.t) == len(wheel.t) - 1
    assert log.warnings == (
        "IMU /imu/data: dropped 1 samples with a repeated stamp",
        "IMU /imu/data: dropped 1 samples with non-finite values",
        "wheel /wheel/odom: dropped 1 samples with non-finite values",
    )


def test_stamps_sorted_and_zero_stamp_falls_back_to_receive_time(tmp_path: Path) -> None:
    """Header stamps, not the receive order, give the times; a zero stamp uses receive time."""
    imu, gnss, *_ = _streams()
    ts = get_typestore(Stores.ROS2_HUMBLE)
    src = tmp_path / "src.mcap"
    write_bag(src, imu=imu, gnss=gnss)
    out = tmp_path / "shuffled"
    with (
        AnyReader([src]) as reader,
        Writer(out, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer,
    ):
        conns = {
            c.topic: writer.add_connection(c.topic, c.msgtype, typestore=ts)
            for c in reader.connections
        }
        for i, (c, t_ns, raw) in enumerate(reader.messages()):
            msg = reader.deserialize(raw, c.msgtype)
            if c.topic == "/imu/data" and i % 50 == 7:
                msg.header.stamp.sec, msg.header.stamp.nanosec = 0, 0
            elif c.topic == "/imu/data" and i % 50 == 9:  # 15 ms late: after the next sample
                ns = msg.header.stamp.nanosec + 15_000_000
                msg.header.stamp.sec += ns // 1_000_000_000
                msg.header.stamp.nanosec = ns % 1_000_000_000
            writer.write(conns[c.topic], t_ns, ts.serialize_cdr(msg, c.msgtype))
    log = load_log(out, cache_dir=tmp_path / "c")
    assert np.all(np.diff(log.imu.t) > 0)
    assert any("out of time order, sorted by stamp" in w for w in log.warnings)
    np.testing.assert_allclose(log.imu.t[[0, -1]], imu.t[[0, -1]], atol=1e-6)
    assert len(log.imu.t) == len(imu.t)


def test_tf_static_rotates_the_imu_into_the_body_frame(tmp_path: Path) -> None:
    imu, gnss, wheel, _ = _streams()
    # imu_link in base_link: yaw -90 deg then roll +90 deg (the Husky mount)
    r_body_imu = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    q = _quat_from_matrix(r_body_imu)
    in_imu = ImuData(imu.t, imu.gyro @ r_body_imu, imu.accel @ r_body_imu)  # R^T v
    path = tmp_path / "tf.bag"
    write_bag(
        path,
        imu=in_imu,
        gnss=gnss,
        wheel=wheel,
        storage="ros1",
        imu_frame="imu_link",
        static_transforms=[StaticTransform("base_link", "imu_link", q)],
    )
    log = load_log(path, cache_dir=tmp_path / "c")
    np.testing.assert_allclose(log.imu.gyro, imu.gyro, atol=1e-12)
    np.testing.assert_allclose(log.imu.accel, imu.accel, atol=1e-12)
    assert "IMU rotated from imu_link into base_link by /tf_static" in log.warnings
    assert {t.topic: t.role for t in log.topics}["/tf_static"] == "tf_static"


def _quat_from_matrix(r: np.ndarray) -> tuple[float, float, float, float]:
    w = 0.5 * np.sqrt(1.0 + np.trace(r))
    return (
        float((r[2, 1] - r[1, 2]) / (4 * w)),
        float((r[0, 2] - r[2, 0]) / (4 * w)),
        float((r[1, 0] - r[0, 1]) / (4 * w)),
        float(w),
    )


@pytest.mark.parametrize(
    ("name", "content", "problem"),
    [
        ("empty.bag", b"", "file is empty"),
        ("text.bag", b"hello, not a bag\n", "not a ROS 1 bag"),
        ("text.mcap", b"hello\n", "not a ROS 2 bag / mcap file"),
        ("log.txt", b"hello\n", "unknown log format '.txt'"),
        # a log given the other format's suffix is named for what it is
        (
            "drive.bag",
            b"\x89MCAP0\r\n" + b"x" * 20,
            "not a ROS 1 bag: it is an MCAP file (name it .mcap)",
        ),
        (
            "drive.mcap",
            b"#ROSBAG V2.0\n" + b"x" * 20,
            "not a ROS 2 bag / mcap file: it is a ROS 1 bag (name it .bag)",
        ),
    ],
)
def test_not_a_bag(tmp_path: Path, name: str, content: bytes, problem: str) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(LogError) as err:
        load_log(path, cache_dir=tmp_path / "c")
    assert str(err.value).startswith(f"{path}: {problem}") and "\n" not in str(err.value)


@pytest.mark.parametrize("storage", ["mcap", "ros1"])
def test_truncated_bag(tmp_path: Path, storage) -> None:
    imu, gnss, *_ = _streams(2000)
    src = tmp_path / ("src.mcap" if storage == "mcap" else "src.bag")
    write_bag(src, imu=imu, gnss=gnss, storage=storage)
    cut = tmp_path / ("cut" + src.suffix)
    cut.write_bytes(src.read_bytes()[: src.stat().st_size // 2])
    with pytest.raises(LogError, match=r"truncated or corrupt \(") as err:
        load_log(cut, cache_dir=tmp_path / "c")
    assert str(err.value).startswith(str(cut))
    assert "('" not in str(err.value) and ",)" not in str(err.value)  # no Python repr


def test_missing_path_and_folder_without_metadata(tmp_path: Path) -> None:
    with pytest.raises(LogError, match="no such file"):
        load_log(tmp_path / "nothing.bag")
    with pytest.raises(LogError, match=r"no metadata\.yaml"):
        load_log(tmp_path)


def test_real_ros1_husky_bag(shared_data: Path) -> None:
    log = load_log(shared_data / "robot_localization" / "test1.bag")
    counts = {t.topic: (t.count, t.role) for t in log.topics}
    assert counts == {
        "/imu/data": (11865, "imu"),
        "/fix": (989, "gnss"),
        "/husky_velocity_controller/odom": (3952, "wheel"),
    }
    assert len(log.imu.t) == 11865 and len(log.gnss.t) == 989
    assert log.wheel is not None and len(log.wheel.t) == 3952 and log.truth is None
    assert log.duration_s == pytest.approx(395.3, abs=0.2)
    distance = np.sum(0.5 * (log.wheel.speed[1:] + log.wheel.speed[:-1]) * np.diff(log.wheel.t))
    assert distance == pytest.approx(358.9, abs=1.0)
    assert np.all(log.gnss.status == 1) and np.all(log.gnss.valid)
    # no tf in the bag: the IMU stays in imu_link, gravity on +y
    assert np.mean(log.imu.accel[:, 1]) == pytest.approx(9.79, abs=0.05)


def test_real_car_mcap_with_truth(shared_data: Path) -> None:
    log = load_log(shared_data / "comma2k19" / "i280.mcap")
    assert (len(log.imu.t), len(log.gnss.t)) == (6256, 579)
    assert log.wheel is not None and len(log.wheel.t) == 4974
    assert log.truth is not None and len(log.truth.t) == 1200
    assert np.all(np.isnan(log.truth.heading))
    assert np.mean(log.imu.accel[:, 2]) == pytest.approx(9.66, abs=0.02)
    assert log.gnss.t[0] == pytest.approx(1533226488.299, abs=0.001)


def test_an_exception_from_the_progress_callback_passes_through(tmp_path: Path) -> None:
    """A caller cancels a load by raising from its progress callback."""
    imu, gnss, *_ = _streams(n=5000)
    path = tmp_path / "log.mcap"
    write_bag(path, imu=imu, gnss=gnss)

    class Cancelled(Exception):
        pass

    def cancel(fraction: float) -> None:
        raise Cancelled

    with pytest.raises(Cancelled):
        load_log(path, cache_dir=tmp_path / "c", progress=cancel)
    assert not list((tmp_path / "c").glob("log-*.npz"))


def test_byte_layout_fast_path_matches_full_deserialisation(tmp_path: Path, monkeypatch) -> None:
    """Fields cut out of the raw bytes equal what rosbags deserialises, for mixed layouts."""
    imu, gnss, wheel, truth = _streams(n=1000)
    a, b = tmp_path / "a.bag", tmp_path / "b.bag"
    write_bag(a, imu=imu, gnss=gnss, wheel=wheel, truth=truth, storage="ros1")
    late = ImuData(imu.t + 0.005, imu.gyro[::-1], imu.accel[::-1])
    write_bag(b, imu=late, storage="ros1", imu_frame="a_much_longer_imu_frame")
    merged = tmp_path / "merged.bag"
    _merge([a, b], merged)  # one IMU topic, two message sizes
    import estimator.io.decode as bagio

    found: list[object] = []
    real = bagio._find_offsets
    monkeypatch.setattr(
        bagio, "_find_offsets", lambda *args: found.append(real(*args)) or found[-1]
    )
    fast = load_log(merged, cache_dir=tmp_path / "fast")
    assert len(found) == 6 and all(offsets is not None for offsets in found)  # IMU: 2 sizes
    monkeypatch.setattr(bagio, "_find_offsets", lambda *args: None)
    slow = load_log(merged, cache_dir=tmp_path / "slow")
    assert len(fast.imu.t) == 2 * len(imu.t)
    for part in ("imu", "gnss", "wheel", "truth"):
        x, y = getattr(fast, part), getattr(slow, part)
        for name in x.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(x, name), getattr(y, name))


def test_cache_keeps_to_its_size_limit(tmp_path: Path, monkeypatch) -> None:
    imu, gnss, *_ = _streams()
    cache = tmp_path / "cache"
    paths = []
    for i in range(3):
        paths.append(tmp_path / f"log{i}.mcap")
        write_bag(paths[-1], imu=ImuData(imu.t + i, imu.gyro, imu.accel), gnss=gnss)
    load_log(paths[0], cache_dir=cache)
    (entry,) = cache.glob("log-*.npz")
    monkeypatch.setattr("estimator.io.cache.CACHE_MAX_BYTES", int(2.5 * entry.stat().st_size))
    load_log(paths[1], cache_dir=cache)
    os.utime(entry, (1.0, 1.0))  # log0 is the least recently used
    load_log(paths[2], cache_dir=cache)
    assert len(list(cache.glob("log-*.npz"))) == 2 and not entry.exists()


def test_a_huge_metadata_yaml_is_refused_from_its_size(tmp_path: Path) -> None:
    """rosbags parses metadata.yaml whole: 150 MB took 46 s and 500 MB. One over
    MAX_METADATA_BYTES is refused before it is read, named, in one line; the bag's files,
    named instead of the folder, are refused alike."""
    imu, gnss, *_ = _streams()
    bag = tmp_path / "sqlbag"
    write_bag(bag, imu=imu, gnss=gnss, storage="sqlite3")
    metadata = bag / "metadata.yaml"
    text = metadata.read_text()
    assert "custom_data: null" in text
    metadata.write_text(
        text.replace("custom_data: null", 'custom_data: {k: "' + "x" * 5_000_000 + '"}')
    )
    assert metadata.stat().st_size > MAX_METADATA_BYTES
    (db3,) = bag.glob("*.db3")
    for given in (bag, db3):
        started = time.perf_counter()
        with pytest.raises(LogError) as err:
            load_log(given, cache_dir=tmp_path / "c")
        assert str(err.value) == (
            f"{metadata}: file is 5.0 MB; a bag's metadata over 4 MB is refused "
            "(it lists topics and files: a few kB)"
        )
        assert time.perf_counter() - started < 1.0


def test_metadata_yaml_within_the_limit_is_read(tmp_path: Path) -> None:
    imu, gnss, *_ = _streams()
    bag = tmp_path / "sqlbag"
    write_bag(bag, imu=imu, gnss=gnss, storage="sqlite3")
    metadata = bag / "metadata.yaml"
    metadata.write_text(
        metadata.read_text().replace(
            "custom_data: null", 'custom_data: {k: "' + "x" * 100_000 + '"}'
        )
    )
    assert len(load_log(bag, cache_dir=tmp_path / "c").imu.t) == len(imu.t)
