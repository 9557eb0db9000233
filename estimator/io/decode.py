"""Decoding the messages of a rosbags reader into float64 columns, and the static transform
tree (/tf_static) that rotates the IMU into the body frame."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimator.io.messages import ODOM_TYPE, PROBE_VALUES, TWIST_TYPE, get_field, set_field
from estimator.io.topics import TopicRoles
from estimator.nav.rotation import dcm_from_quaternion, quaternion_from_ros

F64 = NDArray[np.float64]

BODY_FRAMES = ("base_link", "base_footprint", "body")

_Field = tuple[str, str]  # (dotted message path, numpy kind)
_STAMP: tuple[_Field, ...] = (("header.stamp.sec", "i4"), ("header.stamp.nanosec", "u4"))
_FIELDS: dict[str, tuple[_Field, ...]] = {
    "imu": tuple(
        (f"{v}.{a}", "f8") for v in ("angular_velocity", "linear_acceleration") for a in "xyz"
    ),
    "fix": (
        ("latitude", "f8"),
        ("longitude", "f8"),
        ("altitude", "f8"),
        ("status.status", "i1"),
        ("position_covariance[0]", "f8"),
        ("position_covariance[4]", "f8"),
        ("position_covariance[8]", "f8"),
        ("position_covariance_type", "u1"),
    ),
    ODOM_TYPE: (("twist.twist.linear.x", "f8"),),
    TWIST_TYPE: (("twist.linear.x", "f8"),),
    # the truth attitude's columns, in ROS order (x, y, z, w)
    "pose": tuple((f"pose.pose.orientation.{a}", "f8") for a in "xyzw"),
}
CHUNK = 20_000


class _Stream:
    """Raw messages of one topic, decoded in chunks into float64 columns.

    Every message of one byte length shares its layout (frame ids of constant length), so
    the fields are cut out of the raw bytes at offsets found once per layout by serialising
    probe messages; sampled messages are fully deserialised to confirm. A layout that cannot
    be confirmed (big-endian CDR, odd strings) is decoded message by message.
    """

    def __init__(self, reader: Any, msgtype: str, fields: tuple[_Field, ...]) -> None:
        self.reader = reader
        self.msgtype = msgtype
        self.fields = _STAMP + fields
        self.recv: list[int] = []
        self.raws: list[bytes] = []
        self.chunks: list[F64] = []
        self.layouts: dict[int, list[int] | None] = {}
        self.first: Any = None

    def add(self, recv_ns: int, raw: bytes) -> None:
        if self.first is None:
            self.first = self.reader.deserialize(raw, self.msgtype)
        self.recv.append(recv_ns)
        self.raws.append(bytes(raw))
        if len(self.raws) >= CHUNK:
            self.flush()

    def flush(self) -> None:
        if not self.raws:
            return
        n = len(self.raws)
        out = np.empty((n, len(self.fields)))
        lengths = np.fromiter(map(len, self.raws), np.int64, n)
        for size in np.unique(lengths).tolist():
            idx = np.flatnonzero(lengths == size)
            offsets = self._layout(size, self.raws[idx[0]])
            if offsets is None or not self._cut(out, idx, size, offsets):
                for i in idx.tolist():
                    msg = self.reader.deserialize(self.raws[i], self.msgtype)
                    out[i] = [get_field(msg, f) for f, _ in self.fields]
        recv = np.array(self.recv, np.float64) * 1e-9
        stamp = out[:, 0] + out[:, 1] * 1e-9
        zero = (out[:, 0] == 0) & (out[:, 1] == 0)
        self.chunks.append(np.column_stack([np.where(zero, recv, stamp), out[:, 2:]]))
        self.recv, self.raws = [], []

    def arrays(self) -> tuple[F64, F64]:
        self.flush()
        if not self.chunks:
            return np.zeros(0), np.zeros((0, len(self.fields) - 2))
        all_rows = np.concatenate(self.chunks)
        return all_rows[:, 0].copy(), np.ascontiguousarray(all_rows[:, 1:])

    def _layout(self, size: int, raw: bytes) -> list[int] | None:
        if size not in self.layouts:
            self.layouts[size] = _find_offsets(self.reader, self.msgtype, raw, self.fields)
        return self.layouts[size]

    def _cut(self, out: F64, idx: NDArray[np.intp], size: int, offsets: list[int]) -> bool:
        buf = np.frombuffer(b"".join(self.raws[i] for i in idx.tolist()), np.uint8)
        buf = buf.reshape(len(idx), size)
        for k, ((_, kind), off) in enumerate(zip(self.fields, offsets, strict=True)):
            width = np.dtype(kind).itemsize
            out[idx, k] = buf[:, off : off + width].copy().view("<" + kind)[:, 0]
        probe = np.unique(np.r_[idx[:: max(len(idx) // 8, 1)], idx[-1]])
        for i in probe.tolist():
            msg = self.reader.deserialize(self.raws[i], self.msgtype)
            want = np.array([get_field(msg, f) for f, _ in self.fields])
            if not np.array_equal(want, out[i], equal_nan=True):
                return False
        return True


def _find_offsets(
    reader: Any, msgtype: str, raw: bytes, fields: tuple[_Field, ...]
) -> list[int] | None:
    """Byte offset of every field in messages laid out like ``raw``, or None."""
    ts = reader.typestore
    serialize = ts.serialize_cdr if reader.is2 else ts.serialize_ros1
    try:
        msg = reader.deserialize(raw, msgtype)
        if bytes(serialize(msg, msgtype)) != bytes(raw):
            return None
        offsets = []
        for path, kind in fields:
            a, b = (
                np.frombuffer(serialize(set_field(msg, path, v), msgtype), np.uint8)
                for v in PROBE_VALUES[kind]
            )
            width = np.dtype(kind).itemsize
            if len(a) != len(raw) or len(b) != len(raw):
                return None
            diff = np.flatnonzero(a != b)
            if len(diff) != width or diff[-1] - diff[0] != width - 1:
                return None
            offsets.append(int(diff[0]))
        return offsets
    except Exception:
        return None


def _frame(name: str) -> str:
    return name.strip().lstrip("/")


def rotation_between(edges: Iterable[tuple[str, str, F64]], body: str, target: str) -> F64 | None:
    """R such that v_body = R @ v_target, walking the static transform tree both ways."""
    graph: dict[str, list[tuple[str, F64]]] = {}
    for parent, child, r_parent_child in edges:
        graph.setdefault(parent, []).append((child, r_parent_child))
        graph.setdefault(child, []).append((parent, r_parent_child.T))
    rot = {body: np.eye(3)}
    todo = [body]
    while todo:
        frame = todo.pop()
        for other, r in graph.get(frame, []):
            if other not in rot:
                rot[other] = rot[frame] @ r
                todo.append(other)
    return rot.get(target)


@dataclass(frozen=True)
class Decoded:
    """What :func:`decode` read: per role (times, value columns, frame id), the static
    transforms as (parent, child, R_parent_child), and the frames that may be the body."""

    streams: dict[str, tuple[F64, F64, str]]
    edges: list[tuple[str, str, F64]]
    bad_tf: list[str]
    body_candidates: list[str]


def _roles_to_decode(roles: TopicRoles) -> dict[str, str]:
    """Topic -> role, for every topic decoded into columns."""
    role_of: dict[str, str] = {}
    for role in ("imu", "gnss", "wheel", "truth", "truth_pose"):
        topic = getattr(roles, role)
        if topic is not None:
            role_of[topic] = role
    return role_of


def decode(
    path: Path, reader: Any, roles: TopicRoles, progress: Callable[[float], None] | None
) -> Decoded:
    by_topic: dict[str, list[Any]] = {}
    for conn in reader.connections:
        by_topic.setdefault(conn.topic, []).append(conn)
    role_of = _roles_to_decode(roles)
    streams: dict[str, _Stream] = {}
    for topic, role in role_of.items():
        msgtype = by_topic[topic][0].msgtype
        kind = {"imu": "imu", "gnss": "fix", "truth": "fix", "truth_pose": "pose"}.get(
            role, msgtype
        )
        streams[topic] = _Stream(reader, msgtype, _FIELDS[kind])
    wanted = [c for t in (*streams, roles.tf_static) if t is not None for c in by_topic[t]]
    total = max(sum(int(c.msgcount or 0) for c in wanted), 1)
    step = max(total // 50, 1000)
    edges: list[tuple[str, str, F64]] = []
    bad_tf: list[str] = []
    for done, (conn, recv_ns, raw) in enumerate(reader.messages(connections=wanted), 1):
        stream = streams.get(conn.topic)
        if stream is not None:
            stream.add(recv_ns, raw)
        else:
            for tf in reader.deserialize(raw, conn.msgtype).transforms:
                r = tf.transform.rotation
                parent, child = _frame(tf.header.frame_id), _frame(tf.child_frame_id)
                matrix = dcm_from_quaternion(*quaternion_from_ros(r.x, r.y, r.z, r.w))
                if matrix is None:
                    bad_tf.append(f"{parent} -> {child}")
                else:
                    edges.append((parent, child, matrix))
        if progress is not None and done % step == 0:
            progress(min(done / total, 0.99))
    decoded: dict[str, tuple[F64, F64, str]] = {}
    wheel_child = ""
    for topic, stream in streams.items():
        t, v = stream.arrays()
        frame_id = "" if stream.first is None else _frame(stream.first.header.frame_id)
        decoded[role_of[topic]] = (t, v, frame_id)
        if role_of[topic] == "wheel" and stream.msgtype == ODOM_TYPE and stream.first is not None:
            wheel_child = _frame(stream.first.child_frame_id)
    candidates = [f for f in (wheel_child, *BODY_FRAMES) if f]
    return Decoded(decoded, edges, bad_tf, candidates)
