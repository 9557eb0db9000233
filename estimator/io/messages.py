"""ROS message types routefuse reads and writes, and the field access shared by the bag reader
(:mod:`estimator.io.decode`) and writer (:mod:`estimator.io.bagwrite`): both find a field's byte
offset by serialising two messages that differ in that field only."""

from __future__ import annotations

import dataclasses
import struct
from typing import Any

IMU_TYPE = "sensor_msgs/msg/Imu"
FIX_TYPE = "sensor_msgs/msg/NavSatFix"
ODOM_TYPE = "nav_msgs/msg/Odometry"
TWIST_TYPE = "geometry_msgs/msg/TwistStamped"
TF_TYPE = "tf2_msgs/msg/TFMessage"

PROBE_VALUES: dict[str, tuple[Any, Any]] = {
    # two values per field kind whose encodings differ in every byte
    "f8": (struct.unpack("<d", b"\x11" * 8)[0], struct.unpack("<d", b"\x22" * 8)[0]),
    "i4": (0x11111111, 0x22222222),
    "u4": (0x11111111, 0x22222222),
    "i1": (0x11, 0x22),
    "u1": (0x11, 0x22),
}


def get_field(msg: Any, path: str) -> float:
    """The dotted field ``path`` (``a.b[3]`` for array items) of ``msg`` as a float."""
    obj = msg
    for part in path.split("."):
        if part.endswith("]"):
            name, idx = part[:-1].split("[")
            obj = getattr(obj, name)[int(idx)]
        else:
            obj = getattr(obj, part)
    return float(obj)


def set_field(msg: Any, path: str, value: Any) -> Any:
    """A copy of ``msg`` with the dotted field ``path`` (``a.b[3]`` for array items) set."""
    import numpy as np  # not above: the log registry's names are imported by the CLI's parser

    head, _, rest = path.partition(".")
    if "[" in head:
        name, idx = head[:-1].split("[")
        arr = np.array(getattr(msg, name), copy=True)
        arr[int(idx)] = value
        return dataclasses.replace(msg, **{name: arr})
    if rest:
        return dataclasses.replace(msg, **{head: set_field(getattr(msg, head), rest, value)})
    return dataclasses.replace(msg, **{head: value})
