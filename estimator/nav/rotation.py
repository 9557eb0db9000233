"""Rotations of the navigation model (:mod:`estimator.nav.earth`): body forward-left-up to local
ENU, ``C_nb = Rz(yaw) Ry(-pitch) Rx(roll)``. Quaternions are scalar-first (w, x, y, z)
everywhere in routefuse, as viser has them; ROS messages' (x, y, z, w) are reordered where they
are read."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]


def dcm_from_euler(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> F64:
    """``C_nb = Rz(yaw) Ry(-pitch) Rx(roll)`` for arrays of angles -> (N, 3, 3)."""
    r = np.atleast_1d(np.asarray(roll, np.float64))
    p = np.atleast_1d(np.asarray(pitch, np.float64))
    y = np.atleast_1d(np.asarray(yaw, np.float64))
    cr, sr = np.cos(r), np.sin(r)
    cp, sp = np.cos(p), np.sin(p)
    cy, sy = np.cos(y), np.sin(y)
    c = np.empty((len(r), 3, 3))
    c[:, 0, 0] = cy * cp
    c[:, 0, 1] = -sy * cr - cy * sp * sr
    c[:, 0, 2] = sy * sr - cy * sp * cr
    c[:, 1, 0] = sy * cp
    c[:, 1, 1] = cy * cr - sy * sp * sr
    c[:, 1, 2] = -cy * sr - sy * sp * cr
    c[:, 2, 0] = sp
    c[:, 2, 1] = cp * sr
    c[:, 2, 2] = cp * cr
    return c


def euler_from_dcm(c_nb: ArrayLike) -> F64:
    """(N, 3, 3) ``C_nb`` -> (N, 3) roll, pitch, yaw in the convention of :func:`dcm_from_euler`."""
    c = np.asarray(c_nb, np.float64).reshape(-1, 3, 3)
    pitch = np.arcsin(np.clip(c[:, 2, 0], -1.0, 1.0))
    roll = np.arctan2(c[:, 2, 1], c[:, 2, 2])
    yaw = np.arctan2(c[:, 1, 0], c[:, 0, 0])
    return np.column_stack([roll, pitch, yaw])


def body_rate_from_euler_rates(
    roll: F64, pitch: F64, roll_rate: F64, pitch_rate: F64, yaw_rate: F64
) -> F64:
    """``w_nb_b`` (N, 3) of the rotation :func:`dcm_from_euler` from the Euler angle rates."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    return np.column_stack(
        [
            roll_rate + yaw_rate * sp,
            -pitch_rate * cr + yaw_rate * sr * cp,
            pitch_rate * sr + yaw_rate * cr * cp,
        ]
    )


def quaternion_from_ros(
    x: float, y: float, z: float, w: float
) -> tuple[float, float, float, float]:
    """A ROS message's quaternion, stored (x, y, z, w), in routefuse's order (w, x, y, z)."""
    return w, x, y, z


def dcm_from_quaternion(w: float, x: float, y: float, z: float) -> F64 | None:
    """The rotation matrix of the scalar-first quaternion (w, x, y, z), normalised first, or
    None if it has no direction (zero, NaN, inf)."""
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


def yaw_from_quaternion(w: F64, x: F64, y: F64, z: F64) -> F64:
    """ENU yaw of the body x axis (rad) of unit scalar-first quaternions, element-wise."""
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
