"""Write ROS bags (ROS 2 mcap / sqlite3, ROS 1) from the numpy arrays of a :class:`Log`.

Used by the simulator and by tests. Messages are ROS 2 Humble (or ROS 1 Noetic) standard types
in the conventions of ``shared/data/README.md``: ``/imu/data`` Imu (FLU, specific force),
``/gnss/fix`` NavSatFix (NO_FIX epochs as status -1 with NaN position), ``/wheel/odom`` Odometry
(``twist.twist.linear.x`` = forward speed) or TwistStamped, ``/ground_truth/fix`` NavSatFix and
``/ground_truth/odom`` Odometry whose orientation is the truth attitude (body -> ENU, yaw only).

Building message objects one by one costs more than writing them, so each message type is
serialised once as a template, the byte offset of every varying field is found by serialising
two templates that differ in that field only, and all messages are then stamped out of the
template with vectorised numpy writes. The output is byte-identical for identical arrays.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimator.io.messages import (
    FIX_TYPE,
    IMU_TYPE,
    ODOM_TYPE,
    PROBE_VALUES,
    TF_TYPE,
    TWIST_TYPE,
    set_field,
)
from estimator.log import GnssData, ImuData, TruthData, WheelData

Storage = Literal["mcap", "mcap-folder", "sqlite3", "ros1"]


@dataclass(frozen=True)
class BagTopics:
    """Topic names written for each stream."""

    imu: str = "/imu/data"
    gnss: str = "/gnss/fix"
    wheel: str = "/wheel/odom"
    truth_fix: str = "/ground_truth/fix"
    truth_odom: str = "/ground_truth/odom"
    tf_static: str = "/tf_static"


@dataclass(frozen=True)
class StaticTransform:
    """One /tf_static entry: the pose of ``child`` in ``parent`` (rotation as x, y, z, w)."""

    parent: str
    child: str
    rotation_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)


@cache
def _typestore(storage: Storage) -> Any:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if storage == "ros1":
        ts = get_typestore(Stores.ROS1_NOETIC)
        if TF_TYPE not in ts.types:
            ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF_TYPE))
        return ts
    return get_typestore(Stores.ROS2_HUMBLE)


def _serializer(storage: Storage) -> Callable[[Any, str], bytes]:
    ts = _typestore(storage)
    serialize: Callable[[Any, str], bytes] = (
        ts.serialize_ros1 if storage == "ros1" else ts.serialize_cdr
    )
    return serialize


@dataclass(frozen=True)
class _Template:
    data: bytes
    offsets: dict[str, tuple[int, str]]

    def stamp(self, columns: dict[str, NDArray[Any]]) -> NDArray[np.uint8]:
        """(N, len(data)) bytes: the template with every column written at its offset."""
        n = len(next(iter(columns.values())))
        rows = np.tile(np.frombuffer(self.data, np.uint8), (n, 1))
        for name, values in columns.items():
            off, kind = self.offsets[name]
            raw = np.ascontiguousarray(np.asarray(values).astype("<" + kind))
            rows[:, off : off + raw.itemsize] = raw.view(np.uint8).reshape(n, raw.itemsize)
        return rows


def _template(storage: Storage, msg: Any, msgtype: str, fields: dict[str, str]) -> _Template:
    serialize = _serializer(storage)
    base = serialize(msg, msgtype)
    offsets: dict[str, tuple[int, str]] = {}
    for path, kind in fields.items():
        a, b = (serialize(set_field(msg, path, v), msgtype) for v in PROBE_VALUES[kind])
        diff = np.flatnonzero(np.frombuffer(a, np.uint8) != np.frombuffer(b, np.uint8))
        size = np.dtype(kind).itemsize
        if len(a) != len(base) or len(diff) != size or diff[-1] - diff[0] != size - 1:
            raise RuntimeError(f"cannot locate field {path} of {msgtype}")
        offsets[path] = (int(diff[0]), kind)
    return _Template(base, offsets)


def _header(storage: Storage, frame_id: str) -> Any:
    t = _typestore(storage).types
    stamp = t["builtin_interfaces/msg/Time"](sec=0, nanosec=0)
    if storage == "ros1":
        return t["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
    return t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)


_STAMP = {"header.stamp.sec": "i4", "header.stamp.nanosec": "u4"}


def _stamp_columns(storage: Storage, t_ns: NDArray[np.int64]) -> dict[str, NDArray[Any]]:
    cols: dict[str, NDArray[Any]] = {
        "header.stamp.sec": t_ns // 1_000_000_000,
        "header.stamp.nanosec": t_ns % 1_000_000_000,
    }
    if storage == "ros1":
        cols["header.seq"] = np.arange(len(t_ns))
    return cols


def _fields(storage: Storage, extra: dict[str, str]) -> dict[str, str]:
    seq = {"header.seq": "u4"} if storage == "ros1" else {}
    return {**_STAMP, **seq, **extra}


def _vec3(storage: Storage, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
    return _typestore(storage).types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def _quat(storage: Storage, x: float, y: float, z: float, w: float) -> Any:
    return _typestore(storage).types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)


def _imu_rows(storage: Storage, imu: ImuData, t_ns: NDArray[np.int64], frame: str) -> Any:
    t = _typestore(storage).types
    orientation_cov = np.zeros(9)
    orientation_cov[0] = -1.0
    msg = t[IMU_TYPE](
        header=_header(storage, frame),
        orientation=_quat(storage, 0.0, 0.0, 0.0, 1.0),
        orientation_covariance=orientation_cov,
        angular_velocity=_vec3(storage),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=_vec3(storage),
        linear_acceleration_covariance=np.zeros(9),
    )
    axes = ("x", "y", "z")
    vec = {f"angular_velocity.{a}": "f8" for a in axes}
    vec |= {f"linear_acceleration.{a}": "f8" for a in axes}
    tpl = _template(storage, msg, IMU_TYPE, _fields(storage, vec))
    gyro = np.asarray(imu.gyro, np.float64)
    accel = np.asarray(imu.accel, np.float64)
    cols = _stamp_columns(storage, t_ns)
    for i, a in enumerate(axes):
        cols[f"angular_velocity.{a}"] = gyro[:, i]
        cols[f"linear_acceleration.{a}"] = accel[:, i]
    return tpl.stamp(cols)


def _fix_rows(
    storage: Storage,
    t_ns: NDArray[np.int64],
    lat: ArrayLike,
    lon: ArrayLike,
    alt: ArrayLike,
    status: ArrayLike,
    cov_enu: NDArray[np.float64] | None,
    frame: str,
) -> Any:
    t = _typestore(storage).types
    msg = t[FIX_TYPE](
        header=_header(storage, frame),
        status=t["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
        latitude=0.0,
        longitude=0.0,
        altitude=0.0,
        position_covariance=np.zeros(9),
        position_covariance_type=0,
    )
    extra = {
        "status.status": "i1",
        "latitude": "f8",
        "longitude": "f8",
        "altitude": "f8",
        "position_covariance[0]": "f8",
        "position_covariance[4]": "f8",
        "position_covariance[8]": "f8",
        "position_covariance_type": "u1",
    }
    tpl = _template(storage, msg, FIX_TYPE, _fields(storage, extra))
    n = len(t_ns)
    status_a = np.asarray(status, np.int8)
    lat_a, lon_a, alt_a = (np.asarray(v, np.float64) for v in (lat, lon, alt))
    no_fix = (status_a < 0) | ~(np.isfinite(lat_a) & np.isfinite(lon_a) & np.isfinite(alt_a))
    cov = np.full((n, 3), np.nan) if cov_enu is None else np.asarray(cov_enu, np.float64)
    known = np.all(np.isfinite(cov), axis=1) & ~no_fix
    cov = np.where(known[:, None], cov, 0.0)
    cols = _stamp_columns(storage, t_ns)
    cols |= {
        "status.status": np.where(no_fix, -1, status_a),
        "latitude": np.where(no_fix, np.nan, lat_a),
        "longitude": np.where(no_fix, np.nan, lon_a),
        "altitude": np.where(no_fix, np.nan, alt_a),
        "position_covariance[0]": cov[:, 0],
        "position_covariance[4]": cov[:, 1],
        "position_covariance[8]": cov[:, 2],
        "position_covariance_type": np.where(known, 2, 0),
    }
    return tpl.stamp(cols)


def _odometry(storage: Storage, frame: str, child: str) -> Any:
    t = _typestore(storage).types
    pose = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
        orientation=_quat(storage, 0.0, 0.0, 0.0, 1.0),
    )
    twist = t["geometry_msgs/msg/Twist"](linear=_vec3(storage), angular=_vec3(storage))
    return t[ODOM_TYPE](
        header=_header(storage, frame),
        child_frame_id=child,
        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )


def _wheel_rows(
    storage: Storage,
    wheel: WheelData,
    t_ns: NDArray[np.int64],
    kind: Literal["odometry", "twist"],
    frame: str,
) -> Any:
    speed = np.asarray(wheel.speed, np.float64)
    if kind == "twist":
        t = _typestore(storage).types
        twist = t["geometry_msgs/msg/Twist"](linear=_vec3(storage), angular=_vec3(storage))
        msg = t[TWIST_TYPE](header=_header(storage, frame), twist=twist)
        tpl = _template(storage, msg, TWIST_TYPE, _fields(storage, {"twist.linear.x": "f8"}))
        return tpl.stamp(_stamp_columns(storage, t_ns) | {"twist.linear.x": speed})
    msg = _odometry(storage, "odom", frame)
    field = "twist.twist.linear.x"
    tpl = _template(storage, msg, ODOM_TYPE, _fields(storage, {field: "f8"}))
    return tpl.stamp(_stamp_columns(storage, t_ns) | {field: speed})


def _truth_odom_rows(storage: Storage, truth: TruthData, t_ns: NDArray[np.int64]) -> Any:
    msg = _odometry(storage, "enu", "base_link")
    q = {f"pose.pose.orientation.{a}": "f8" for a in ("x", "y", "z", "w")}
    tpl = _template(storage, msg, ODOM_TYPE, _fields(storage, q))
    half = 0.5 * np.asarray(truth.heading, np.float64)
    zeros = np.zeros_like(half)
    cols = _stamp_columns(storage, t_ns) | {
        "pose.pose.orientation.x": zeros,
        "pose.pose.orientation.y": zeros,
        "pose.pose.orientation.z": np.sin(half),
        "pose.pose.orientation.w": np.cos(half),
    }
    return tpl.stamp(cols)


def _tf_static_rows(storage: Storage, transforms: Sequence[StaticTransform]) -> Any:
    t = _typestore(storage).types
    items = [
        t["geometry_msgs/msg/TransformStamped"](
            header=_header(storage, tf.parent),
            child_frame_id=tf.child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=_vec3(storage, *map(float, tf.translation)),
                rotation=_quat(storage, *map(float, tf.rotation_xyzw)),
            ),
        )
        for tf in transforms
    ]
    data = _serializer(storage)(t[TF_TYPE](transforms=items), TF_TYPE)
    return np.frombuffer(data, np.uint8)[None, :]


def _to_ns(t: ArrayLike, what: str) -> NDArray[np.int64]:
    t_a = np.asarray(t, np.float64)
    if t_a.ndim != 1 or not np.all(np.isfinite(t_a)) or np.any(t_a < 0):
        raise ValueError(f"{what} times must be a 1-D array of finite non-negative seconds")
    return np.round(t_a * 1e9).astype(np.int64)


def write_bag(
    path: str | Path,
    *,
    imu: ImuData | None = None,
    gnss: GnssData | None = None,
    wheel: WheelData | None = None,
    truth: TruthData | None = None,
    storage: Storage = "mcap",
    topics: BagTopics = BagTopics(),
    wheel_type: Literal["odometry", "twist"] = "odometry",
    imu_frame: str = "base_link",
    static_transforms: Sequence[StaticTransform] = (),
    header_stamps: Mapping[Literal["imu", "gnss", "wheel"], NDArray[np.float64]] | None = None,
) -> dict[str, int]:
    """Write the given streams to one bag and return the message count per topic.

    ``storage="mcap"`` writes one bare ``.mcap`` file (ROS 2 bag v9, zstd chunks),
    ``"mcap-folder"`` and ``"sqlite3"`` a ROS 2 bag folder, ``"ros1"`` a ROS 1 ``.bag``.
    The receive time of each message is its header stamp; messages are written in time order
    (ties by stream). ``header_stamps`` gives a stream header stamps of their own (a sensor
    clock that jumps while the recorder's receive times, the streams' ``t``, run on).
    Arrays are written as given (NaN and duplicate stamps included), so tests can build bad logs.
    """
    out = Path(path)
    if out.exists():
        raise FileExistsError(f"{out}: already exists")
    streams: list[tuple[str, str, NDArray[np.int64], NDArray[np.uint8]]] = []
    if static_transforms:
        first = [_to_ns(d.t, "first")[:1] for d in (imu, gnss, wheel, truth) if d is not None]
        t0 = min((int(f[0]) for f in first if len(f)), default=0)
        rows = _tf_static_rows(storage, static_transforms)
        streams.append((topics.tf_static, TF_TYPE, np.array([t0], np.int64), rows))
    headers = dict(header_stamps or {})

    def header(name: Literal["imu", "gnss", "wheel"], t_ns: NDArray[np.int64]) -> NDArray[np.int64]:
        return _to_ns(headers[name], name) if name in headers else t_ns

    if imu is not None:
        t_ns = _to_ns(imu.t, "IMU")
        rows = _imu_rows(storage, imu, header("imu", t_ns), imu_frame)
        streams.append((topics.imu, IMU_TYPE, t_ns, rows))
    if gnss is not None:
        t_ns = _to_ns(gnss.t, "GNSS")
        rows = _fix_rows(
            storage,
            header("gnss", t_ns),
            gnss.lat,
            gnss.lon,
            gnss.alt,
            gnss.status,
            gnss.cov_enu,
            "gnss",
        )
        streams.append((topics.gnss, FIX_TYPE, t_ns, rows))
    if wheel is not None:
        t_ns = _to_ns(wheel.t, "wheel")
        wtype = TWIST_TYPE if wheel_type == "twist" else ODOM_TYPE
        rows = _wheel_rows(storage, wheel, header("wheel", t_ns), wheel_type, "base_link")
        streams.append((topics.wheel, wtype, t_ns, rows))
    if truth is not None:
        t_ns = _to_ns(truth.t, "truth")
        status = np.full(len(t_ns), 2, np.int8)
        rows = _fix_rows(storage, t_ns, truth.lat, truth.lon, truth.alt, status, None, "base_link")
        streams.append((topics.truth_fix, FIX_TYPE, t_ns, rows))
        has_heading = np.isfinite(np.asarray(truth.heading, np.float64))
        if has_heading.any():
            sub = TruthData(
                t=np.asarray(truth.t)[has_heading],
                lat=np.asarray(truth.lat)[has_heading],
                lon=np.asarray(truth.lon)[has_heading],
                alt=np.asarray(truth.alt)[has_heading],
                heading=np.asarray(truth.heading)[has_heading],
            )
            t_h = t_ns[has_heading]
            streams.append((topics.truth_odom, ODOM_TYPE, t_h, _truth_odom_rows(storage, sub, t_h)))
    _write_streams(out, storage, streams)
    return {topic: len(t) for topic, _, t, _ in streams}


def _write_streams(
    out: Path,
    storage: Storage,
    streams: list[tuple[str, str, NDArray[np.int64], NDArray[np.uint8]]],
) -> None:
    times = np.concatenate([s[2] for s in streams]) if streams else np.zeros(0, np.int64)
    none = [np.zeros(0, np.int64)]
    which = np.concatenate([np.full(len(s[2]), k) for k, s in enumerate(streams)] or none)
    index = np.concatenate([np.arange(len(s[2])) for s in streams] or none).astype(np.intp)
    order = np.lexsort((index, which, times))
    ts = _typestore(storage)
    if storage == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        writer1 = Writer1(out)
        writer1.open()
        try:
            conns = [
                writer1.add_connection(
                    topic, mtype, typestore=ts, latching=1 if mtype == TF_TYPE else None
                )
                for topic, mtype, _, _ in streams
            ]
            _emit(writer1.write, conns, streams, times, which, index, order)
        finally:
            writer1.close()
        return

    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    bare = storage == "mcap"
    tmp = Path(tempfile.mkdtemp(prefix=".routefuse-bag-", dir=out.parent)) if bare else None
    bagdir = tmp / out.stem if tmp is not None else out
    try:
        plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
        writer = Writer(bagdir, version=9, storage_plugin=plugin)
        if plugin == StoragePlugin.MCAP:
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        writer.open()
        try:
            conns = [
                writer.add_connection(topic, mtype, typestore=ts) for topic, mtype, _, _ in streams
            ]
            _emit(writer.write, conns, streams, times, which, index, order)
        finally:
            writer.close()
        if tmp is not None:
            shutil.move(str(bagdir / f"{out.stem}.mcap"), str(out))
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def _emit(
    write: Callable[[Any, int, bytes], None],
    conns: list[Any],
    streams: list[tuple[str, str, NDArray[np.int64], NDArray[np.uint8]]],
    times: NDArray[np.int64],
    which: NDArray[Any],
    index: NDArray[np.intp],
    order: NDArray[np.intp],
) -> None:
    rows = [s[3] for s in streams]
    for k, i, t in zip(
        which[order].tolist(), index[order].tolist(), times[order].tolist(), strict=True
    ):
        write(conns[k], t, rows[k][i].tobytes())
