"""Read a ROS 1 ``.bag``, a ROS 2 bag folder (sqlite3 or mcap) or a bare ``.mcap`` into a
:class:`Log` of numpy arrays.

Topics are found by message type. Decoded arrays are cached (keyed by a hash of the file bytes,
the topic choice and :data:`CACHE_VERSION`) so the second load of a log is near-instant.

Repairs, each reported in ``Log.warnings``: samples are sorted by time, exact duplicate stamps
are dropped (the first is kept), IMU and wheel samples with non-finite values are dropped. GNSS
fixes without a position are kept (they mark an outage) and are invalid by ``GnssData.valid``;
IMU and wheel samples with physically impossible values (a corrupt message: beyond
:data:`IMU_LIMITS`, :data:`WHEEL_LIMIT`) are dropped;
a fix whose status says "fix" but whose position is not finite or out of range becomes NO_FIX
(with a NaN position),
and a zero, negative or non-finite position variance becomes unknown (NaN). Irregular IMU
sample intervals are reported, not changed. See ``docs/robustness.md``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimator.errors import LogError
from estimator.log import GnssData, ImuData, Log, TopicInfo, TruthData, WheelData

CACHE_VERSION = 4
CACHE_MAX_BYTES = 2_000_000_000
"""Least recently used cache entries are removed beyond this total size."""
MIN_IMU_SAMPLES = 10

IMU_TYPES = ("sensor_msgs/msg/Imu",)
FIX_TYPES = ("sensor_msgs/msg/NavSatFix",)
ODOM_TYPE = "nav_msgs/msg/Odometry"
TWIST_TYPE = "geometry_msgs/msg/TwistStamped"
WHEEL_TYPES = (ODOM_TYPE, TWIST_TYPE)
TF_TYPE = "tf2_msgs/msg/TFMessage"
BODY_FRAMES = ("base_link", "base_footprint", "body")
ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"
"""First bytes of a ROS 1 bag and of an mcap file: checked before the (whole-file) content hash,
so a large file of the wrong kind is refused at once."""

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class TopicChoice:
    """Topics picked by the user; ``None`` lets the loader find the topic by its type."""

    imu: str | None = None
    gnss: str | None = None
    wheel: str | None = None
    truth: str | None = None

    @classmethod
    def from_args(cls, args: Any) -> TopicChoice:
        """From the ``--imu-topic`` ... options of :func:`commands._common.add_topic_options`."""
        return cls(
            imu=getattr(args, "imu_topic", None),
            gnss=getattr(args, "gnss_topic", None),
            wheel=getattr(args, "wheel_topic", None),
            truth=getattr(args, "truth_topic", None),
        )


AUTO_TOPICS = TopicChoice()
"""Every topic found by its type."""


def is_truth_topic(topic: str) -> bool:
    name = topic.lower()
    return "truth" in name or "groundtruth" in name


# ---------------------------------------------------------------------------------------------
# Opening the file
# ---------------------------------------------------------------------------------------------


def _bag_paths(path: Path) -> Path:
    """The path AnyReader should open, or a LogError saying why this is not a log."""
    if not path.exists():
        raise LogError(path, "no such file or folder")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise LogError(path, "folder is not a ROS 2 bag (it has no metadata.yaml)")
        return path
    suffix = path.suffix.lower()
    if suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file():
        return path.parent
    if suffix == ".db3":
        raise LogError(path, "a .db3 file is read with its bag folder (metadata.yaml is missing)")
    if suffix not in (".bag", ".mcap"):
        raise LogError(
            path,
            f"unknown log format '{path.suffix or path.name}': expected a ROS 1 .bag, "
            "a .mcap file or a ROS 2 bag folder",
        )
    if path.stat().st_size == 0:
        raise LogError(path, "file is empty")
    magic = ROS1_MAGIC if suffix == ".bag" else MCAP_MAGIC
    try:
        with path.open("rb") as fh:
            head = fh.read(len(magic))
    except OSError as exc:
        raise LogError(path, f"cannot open the file ({exc.strerror or exc})") from None
    if head != magic:
        kind = "ROS 1 bag" if suffix == ".bag" else "ROS 2 bag / mcap file"
        raise LogError(path, f"not a {kind} (it does not start with {magic!r})")
    return path


class _CallbackRaised(Exception):
    """Carries an exception raised by the caller's progress callback (e.g. a cancellation)
    through :func:`_reading` unchanged."""

    def __init__(self, exc: Exception) -> None:
        self.exc = exc


def _guarded(progress: Callable[[float], None] | None) -> Callable[[float], None] | None:
    if progress is None:
        return None

    def report(fraction: float) -> None:
        try:
            progress(fraction)
        except Exception as exc:
            raise _CallbackRaised(exc) from exc

    return report


@contextlib.contextmanager
def _reading(path: Path) -> Any:
    """Turn rosbags' (and the storage libraries') exceptions into one-line LogErrors."""
    try:
        yield
    except LogError:
        raise
    except _CallbackRaised as passed:
        raise passed.exc from None
    except Exception as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if reason.lower().startswith("file magic is invalid"):
            kind = "ROS 1 bag" if path.suffix.lower() == ".bag" else "ROS 2 bag / mcap file"
            raise LogError(path, f"not a {kind} ({reason})") from None
        raise LogError(
            path, f"cannot read the bag, it is truncated or corrupt ({reason})"
        ) from None


# ---------------------------------------------------------------------------------------------
# Topic discovery
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Roles:
    imu: str
    gnss: str
    wheel: str | None
    truth: str | None
    truth_pose: str | None
    tf_static: str | None

    def role_of(self, topic: str) -> str:
        for role in ("imu", "gnss", "wheel", "truth", "truth_pose", "tf_static"):
            if getattr(self, role) == topic:
                return role
        return ""


def _listing(types: dict[str, str]) -> str:
    return ", ".join(f"{t} ({m.split('/')[-1]})" for t, m in sorted(types.items())) or "none"


def _pick(
    path: Path,
    types: dict[str, str],
    *,
    kind: str,
    accepted: tuple[str, ...],
    chosen: str | None,
    truth: bool,
    required: bool,
    taken: frozenset[str] = frozenset(),
) -> str | None:
    if chosen is not None:
        if chosen not in types:
            raise LogError(path, f"no topic {chosen} (--{kind}-topic); topics: {_listing(types)}")
        if types[chosen] not in accepted:
            raise LogError(
                path,
                f"--{kind}-topic {chosen} is a {types[chosen]}, expected " + " or ".join(accepted),
            )
        return chosen
    found = sorted(
        t
        for t, m in types.items()
        if m in accepted and is_truth_topic(t) == truth and t not in taken
    )
    if len(found) == 1:
        return found[0]
    if not found:
        if required:
            wanted = " or ".join(a.split("/")[-1] for a in accepted)
            raise LogError(path, f"no {kind.upper()} topic ({wanted}); topics: {_listing(types)}")
        return None
    raise LogError(
        path,
        f"several {kind} topics: {', '.join(found)}; choose one with --{kind}-topic "
        f"(topics: {_listing(types)})",
    )


def _roles(path: Path, types: dict[str, str], choice: TopicChoice) -> _Roles:
    """Chosen topics first; a topic the user chose for one role is no candidate for another."""
    taken = frozenset(t for t in (choice.imu, choice.gnss, choice.wheel, choice.truth) if t)

    def pick(kind: str, accepted: tuple[str, ...], *, truth: bool = False) -> str | None:
        return _pick(
            path,
            types,
            kind=kind,
            accepted=accepted,
            chosen=getattr(choice, kind),
            truth=truth,
            required=kind in ("imu", "gnss"),
            taken=taken,
        )

    imu = pick("imu", IMU_TYPES)
    gnss = pick("gnss", FIX_TYPES)
    wheel = pick("wheel", WHEEL_TYPES)
    truth = pick("truth", FIX_TYPES, truth=True)
    poses = sorted(t for t, m in types.items() if m == ODOM_TYPE and is_truth_topic(t))
    truth_pose = poses[0] if truth is not None and len(poses) == 1 else None
    tf = next((t for t, m in types.items() if m == TF_TYPE and t.endswith("tf_static")), None)
    assert imu is not None and gnss is not None
    return _Roles(imu, gnss, wheel, truth, truth_pose, tf)


# ---------------------------------------------------------------------------------------------
# Decoding
# ---------------------------------------------------------------------------------------------


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
    "pose": tuple((f"pose.pose.orientation.{a}", "f8") for a in "xyzw"),
}
CHUNK = 20_000


def _get(msg: Any, path: str) -> float:
    obj = msg
    for part in path.split("."):
        if part.endswith("]"):
            name, idx = part[:-1].split("[")
            obj = getattr(obj, name)[int(idx)]
        else:
            obj = getattr(obj, part)
    return float(obj)


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
                    out[i] = [_get(msg, f) for f, _ in self.fields]
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
            want = np.array([_get(msg, f) for f, _ in self.fields])
            if not np.array_equal(want, out[i], equal_nan=True):
                return False
        return True


def _find_offsets(
    reader: Any, msgtype: str, raw: bytes, fields: tuple[_Field, ...]
) -> list[int] | None:
    """Byte offset of every field in messages laid out like ``raw``, or None."""
    from estimator.io.bagwrite import _PROBE, _set

    ts = reader.typestore
    serialize = ts.serialize_cdr if reader.is2 else ts.serialize_ros1
    try:
        msg = reader.deserialize(raw, msgtype)
        if bytes(serialize(msg, msgtype)) != bytes(raw):
            return None
        offsets = []
        for path, kind in fields:
            a, b = (
                np.frombuffer(serialize(_set(msg, path, v), msgtype), np.uint8)
                for v in _PROBE[kind]
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


def _quat_to_matrix(x: float, y: float, z: float, w: float) -> F64 | None:
    """The rotation matrix of a quaternion, or None if it has no direction (zero, NaN, inf)."""
    with np.errstate(all="ignore"):
        n = float(np.sqrt(x * x + y * y + z * z + w * w))
    if not (np.isfinite(n) and n > 1e-9):
        return None
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _frame(name: str) -> str:
    return name.strip().lstrip("/")


def _rotation_between(edges: Iterable[tuple[str, str, F64]], body: str, target: str) -> F64 | None:
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


def _decode(
    path: Path, reader: Any, roles: _Roles, progress: Callable[[float], None] | None
) -> dict[str, Any]:
    by_topic: dict[str, list[Any]] = {}
    for conn in reader.connections:
        by_topic.setdefault(conn.topic, []).append(conn)
    streams: dict[str, _Stream] = {}
    role_of: dict[str, str] = {}
    for role in ("imu", "gnss", "wheel", "truth", "truth_pose"):
        topic = getattr(roles, role)
        if topic is None:
            continue
        msgtype = by_topic[topic][0].msgtype
        kind = {"imu": "imu", "gnss": "fix", "truth": "fix", "truth_pose": "pose"}.get(
            role, msgtype
        )
        streams[topic] = _Stream(reader, msgtype, _FIELDS[kind])
        role_of[topic] = role
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
                matrix = _quat_to_matrix(r.x, r.y, r.z, r.w)
                if matrix is None:
                    bad_tf.append(f"{parent} -> {child}")
                else:
                    edges.append((parent, child, matrix))
        if progress is not None and done % step == 0:
            progress(min(done / total, 0.99))
    out: dict[str, Any] = {"edges": edges, "bad_tf": bad_tf}
    wheel_child = ""
    for topic, stream in streams.items():
        t, v = stream.arrays()
        frame_id = "" if stream.first is None else _frame(stream.first.header.frame_id)
        out[role_of[topic]] = (t, v, frame_id)
        if role_of[topic] == "wheel" and stream.msgtype == ODOM_TYPE and stream.first is not None:
            wheel_child = _frame(stream.first.child_frame_id)
    out["body_candidates"] = [f for f in (wheel_child, *BODY_FRAMES) if f]
    return out


# ---------------------------------------------------------------------------------------------
# Repair and assembly
# ---------------------------------------------------------------------------------------------


IMU_LIMITS = (100.0,) * 3 + (2000.0,) * 3
"""|gyro| rad/s and |accel| m/s^2 beyond any vehicle IMU's range: such samples are corrupt."""
WHEEL_LIMIT = 200.0
"""|speed| m/s beyond any vehicle: a corrupt wheel sample."""
MAX_ABS_ALTITUDE_M = 100_000.0


def _clean(
    name: str,
    t: F64,
    v: F64,
    warnings: list[str],
    *,
    drop_nonfinite: bool,
    limits: tuple[float, ...] | None = None,
) -> tuple[F64, F64]:
    order = np.argsort(t, kind="stable")
    if np.any(order != np.arange(len(t))):
        moved = int(np.count_nonzero(np.diff(t) < 0))
        warnings.append(f"{name}: {moved} samples out of time order, sorted by stamp")
        t, v = t[order], v[order]
    dup = np.r_[False, np.diff(t) == 0]
    if dup.any():
        warnings.append(f"{name}: dropped {int(dup.sum())} samples with a repeated stamp")
        t, v = t[~dup], v[~dup]
    bad = ~np.isfinite(t)
    if drop_nonfinite:
        bad |= ~np.all(np.isfinite(v), axis=1)
    if bad.any():
        warnings.append(f"{name}: dropped {int(bad.sum())} samples with non-finite values")
        t, v = t[~bad], v[~bad]
    if limits is not None:
        wild = np.any(np.abs(v) > np.asarray(limits), axis=1)
        if wild.any():
            warnings.append(
                f"{name}: dropped {int(wild.sum())} samples with physically impossible values "
                f"(beyond {', '.join(f'{x:g}' for x in dict.fromkeys(limits))})"
            )
            t, v = t[~wild], v[~wild]
    return t, v


IRREGULAR_FRACTION = 0.01
"""An IMU stream is reported as irregular when more than this fraction of its sample intervals
is off the median interval by more than half of it (dropped samples, jittery stamps)."""


def _note_irregular(name: str, t: F64, warnings: list[str]) -> None:
    """Irregular IMU intervals need no repair (the filter integrates over the actual
    intervals), but they degrade the mechanisation, so they are reported."""
    dt = np.diff(t)
    if len(dt) < 2:
        return
    med = float(np.median(dt))
    off = np.abs(dt - med) > 0.5 * med
    if np.mean(off) > IRREGULAR_FRACTION:
        warnings.append(
            f"{name}: irregular sample intervals ({100 * np.mean(off):.0f} % differ from the "
            f"median {1e3 * med:.1f} ms by more than half; longest {1e3 * float(dt.max()):.0f} "
            "ms), integrated over the actual intervals"
        )


def _assemble(
    path: Path, roles: _Roles, raw: dict[str, Any], types: dict[str, str], counts: dict[str, int]
) -> Log:
    warnings: list[str] = []
    t, v, imu_frame = raw["imu"]
    t, v = _clean(f"IMU {roles.imu}", t, v, warnings, drop_nonfinite=True, limits=IMU_LIMITS)
    if len(t) < MIN_IMU_SAMPLES:
        raise LogError(
            path, f"too few IMU samples on {roles.imu}: {len(t)} (need at least {MIN_IMU_SAMPLES})"
        )
    _note_irregular(f"IMU {roles.imu}", t, warnings)
    gyro, accel = v[:, :3], v[:, 3:6]
    body = next((b for b in raw["body_candidates"] if b), "base_link")
    if raw["bad_tf"]:
        warnings.append(
            f"/tf_static: ignored {len(raw['bad_tf'])} transforms with a zero or non-finite "
            f"rotation ({', '.join(raw['bad_tf'][:3])})"
        )
    if raw["edges"] and imu_frame and imu_frame != body:
        rot = _rotation_between(raw["edges"], body, imu_frame)
        if rot is not None:
            gyro, accel = gyro @ rot.T, accel @ rot.T
            warnings.append(f"IMU rotated from {imu_frame} into {body} by /tf_static")
        else:
            warnings.append(f"IMU frame {imu_frame}: no /tf_static path to {body}, not rotated")
    imu = ImuData(t, np.ascontiguousarray(gyro), np.ascontiguousarray(accel))

    gt, gv = _clean(f"GNSS {roles.gnss}", *raw["gnss"][:2], warnings, drop_nonfinite=False)
    if len(gt) == 0:
        raise LogError(path, f"GNSS topic {roles.gnss} has no messages")
    gnss = _gnss(gt, gv, f"GNSS {roles.gnss}", warnings)
    if not gnss.valid.any():
        warnings.append(f"GNSS {roles.gnss}: no valid fix in the whole log")

    wheel = None
    if "wheel" in raw:
        wt, wv = _clean(
            f"wheel {roles.wheel}",
            *raw["wheel"][:2],
            warnings,
            drop_nonfinite=True,
            limits=(WHEEL_LIMIT,),
        )
        wheel = WheelData(wt, wv[:, 0].copy()) if len(wt) else None

    truth = None
    if "truth" in raw:
        tt, tv = _clean(f"truth {roles.truth}", *raw["truth"][:2], warnings, drop_nonfinite=False)
        heading = np.full(len(tt), np.nan)
        if "truth_pose" in raw:
            pt, pv = _clean(
                f"truth {roles.truth_pose}",
                *raw["truth_pose"][:2],
                warnings,
                drop_nonfinite=True,
            )
            if len(pt):
                x, y, z, w = pv.T
                yaw = np.unwrap(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))
                inside = (tt >= pt[0]) & (tt <= pt[-1])
                heading[inside] = np.angle(np.exp(1j * np.interp(tt[inside], pt, yaw)))
        if len(tt):
            truth = TruthData(tt, tv[:, 0].copy(), tv[:, 1].copy(), tv[:, 2].copy(), heading)

    topics = tuple(
        TopicInfo(topic, types[topic], counts[topic], roles.role_of(topic))
        for topic in sorted(types)
    )
    return Log(str(path), imu, gnss, wheel, truth, topics, tuple(warnings))


def _gnss(t: F64, v: F64, name: str, warnings: list[str]) -> GnssData:
    """Fixes with a status but no usable position become NO_FIX; a variance that is not a
    positive number becomes unknown (NaN: the filter then uses its default sigma)."""
    status = np.where(np.isfinite(v[:, 3]), v[:, 3], -1).astype(np.int8)
    lat, lon, alt = v[:, 0].copy(), v[:, 1].copy(), v[:, 2].copy()
    with np.errstate(invalid="ignore"):
        no_pos = ~(
            np.isfinite(lat)
            & np.isfinite(lon)
            & np.isfinite(alt)
            & (np.abs(lat) <= 90.0)
            & (np.abs(lon) <= 180.0)
            & (np.abs(alt) <= MAX_ABS_ALTITUDE_M)
        )
    bad_pos = no_pos & (status >= 0)
    if bad_pos.any():
        warnings.append(
            f"{name}: {int(bad_pos.sum())} fixes without a finite, in-range position, "
            "treated as no fix"
        )
    status[no_pos] = -1
    lat[no_pos], lon[no_pos], alt[no_pos] = np.nan, np.nan, np.nan  # no inf, no 1e300
    cov = v[:, 4:7].copy()
    cov[(status < 0) | (v[:, 7] == 0)] = np.nan
    with np.errstate(invalid="ignore"):
        bad_cov = np.isfinite(cov).any(axis=1) & ~np.all(np.isfinite(cov) & (cov > 0), axis=1)
    if bad_cov.any():
        warnings.append(
            f"{name}: {int(bad_cov.sum())} fixes with a zero, negative or non-finite variance, "
            "treated as unknown (the filter's default sigma is used)"
        )
        cov[bad_cov] = np.nan
    return GnssData(t, lat, lon, alt, status, cov)


# ---------------------------------------------------------------------------------------------
# Cache
# ---------------------------------------------------------------------------------------------


def default_cache_dir() -> Path:
    """``$ROUTEFUSE_CACHE_DIR``, else ``$XDG_CACHE_HOME/routefuse``, else ``~/.cache/routefuse``."""
    if env := os.environ.get("ROUTEFUSE_CACHE_DIR"):
        return Path(env)
    if xdg := os.environ.get("XDG_CACHE_HOME"):
        return Path(xdg) / "routefuse"
    return Path.home() / ".cache" / "routefuse"


def _files_of(path: Path) -> list[Path]:
    return sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]


def _content_hash(path: Path, cache: Path | None) -> str:
    """sha256 of the log's bytes; a (path, size, mtime) memo in the cache skips re-hashing."""
    files = _files_of(path)
    stat_key = hashlib.sha256(
        json.dumps(
            [[str(f.resolve()), f.stat().st_size, f.stat().st_mtime_ns] for f in files]
        ).encode()
    ).hexdigest()[:32]
    memo = cache / f"stat-{stat_key}.txt" if cache is not None else None
    if memo is not None and memo.is_file():
        text = memo.read_text().strip()
        if len(text) == 64:
            return text
    h = hashlib.sha256()
    for f in files:
        h.update(str(f.relative_to(path) if path.is_dir() else "").encode())
        with f.open("rb") as fh:
            while chunk := fh.read(1 << 20):
                h.update(chunk)
    digest = h.hexdigest()
    if memo is not None:
        _atomic_write(memo, digest.encode())
    return digest


def _atomic_write(target: Path, data: bytes) -> None:
    with contextlib.suppress(OSError):
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".tmp-")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, target)


def _to_npz(log: Log) -> dict[str, Any]:
    arrays: dict[str, Any] = {}
    for name in ("imu", "gnss", "wheel", "truth"):
        part = getattr(log, name)
        if part is not None:
            for f in dataclasses.fields(part):
                arrays[f"{name}.{f.name}"] = getattr(part, f.name)
    meta = {"topics": [dataclasses.asdict(t) for t in log.topics], "warnings": list(log.warnings)}
    arrays["meta"] = np.array(json.dumps(meta))
    return arrays


def _from_npz(path: Path, data: Any) -> Log:
    def part(name: str, cls: type) -> Any:
        keys = [f.name for f in dataclasses.fields(cls)]
        if f"{name}.{keys[0]}" not in data:
            return None
        return cls(**{k: data[f"{name}.{k}"] for k in keys})

    meta = json.loads(str(data["meta"]))
    return Log(
        str(path),
        part("imu", ImuData),
        part("gnss", GnssData),
        part("wheel", WheelData),
        part("truth", TruthData),
        tuple(TopicInfo(**t) for t in meta["topics"]),
        tuple(meta["warnings"]),
    )


def _save(target: Path, log: Log) -> None:
    with contextlib.suppress(OSError):
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".tmp-", suffix=".npz")
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **_to_npz(log))
        os.replace(tmp, target)
        _prune(target.parent, keep=target)


def _prune(cache: Path, *, keep: Path, max_bytes: int | None = None) -> None:
    """Remove the least recently used entries until the cache fits in ``max_bytes``."""
    limit = CACHE_MAX_BYTES if max_bytes is None else max_bytes
    entries = []
    for p in cache.glob("log-*.npz"):
        with contextlib.suppress(OSError):
            st = p.stat()
            entries.append((st.st_mtime, st.st_size, p))
    total = sum(size for _, size, _ in entries)
    for _, size, p in sorted(entries):
        if total <= limit:
            break
        if p != keep:
            with contextlib.suppress(OSError):
                p.unlink()
                total -= size


# ---------------------------------------------------------------------------------------------
# Public entry point
# ---------------------------------------------------------------------------------------------


def load_log(
    path: str | Path,
    *,
    topics: TopicChoice = TopicChoice(),
    cache_dir: Path | None = None,
    progress: Callable[[float], None] | None = None,
) -> Log:
    """Decode a log into numpy arrays (from the cache when this file was decoded before).

    Raises :class:`LogError` (one line naming the file) for anything that is not a readable
    bag with an IMU and a GNSS topic.
    """
    path = Path(path)
    bag = _bag_paths(path)
    cache = cache_dir if cache_dir is not None else default_cache_dir()
    key = hashlib.sha256(
        json.dumps([_content_hash(bag, cache), dataclasses.astuple(topics), CACHE_VERSION]).encode()
    ).hexdigest()[:40]
    entry = cache / f"log-{key}.npz"
    if entry.is_file():
        try:
            with np.load(entry, allow_pickle=False) as data:
                log = _from_npz(path, data)
            with contextlib.suppress(OSError):
                os.utime(entry)  # recently used: pruned last
            if progress is not None:
                progress(1.0)
            return log
        except (OSError, ValueError, KeyError, TypeError):
            pass
    log = _read(path, bag, topics, progress)
    _save(entry, log)
    if progress is not None:
        progress(1.0)
    return log


def _read(
    path: Path, bag: Path, choice: TopicChoice, progress: Callable[[float], None] | None
) -> Log:
    from rosbags.highlevel import AnyReader

    with _reading(path), AnyReader([bag]) as reader:
        types: dict[str, str] = {}
        counts: dict[str, int] = {}
        for conn in reader.connections:
            types.setdefault(conn.topic, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + int(conn.msgcount or 0)
        roles = _roles(path, types, choice)
        raw = _decode(path, reader, roles, _guarded(progress))
    return _assemble(path, roles, raw, types, counts)


def describe_topics(path: str | Path) -> dict[str, tuple[str, int]]:
    """Topic -> (message type, count) without decoding messages (for error messages, info)."""
    p = Path(path)
    bag = _bag_paths(p)
    from rosbags.highlevel import AnyReader

    out: dict[str, tuple[str, int]] = {}
    with _reading(p), AnyReader([bag]) as reader:
        for conn in reader.connections:
            mtype, n = out.get(conn.topic, (conn.msgtype, 0))
            out[conn.topic] = (mtype, n + int(conn.msgcount or 0))
    return out
