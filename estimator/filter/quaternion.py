"""Compiled rotation helpers of the filter kernels. Quaternions are scalar-first (w, x, y, z),
body FLU -> ENU, as in :mod:`estimator.nav.rotation` (which holds the numpy side); these live
here because numba kernels can only call compiled functions."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from estimator.filter.compiled import kernel
from estimator.filter.layout import X_QUAT

F64 = NDArray[np.float64]


@kernel
def quat_to_dcm(q: F64, C: F64) -> None:
    """``C`` <- the body->ENU matrix of the scalar-first quaternion ``q`` = (w, x, y, z)."""
    dcm_of(q[0], q[1], q[2], q[3], C)


@kernel
def dcm_of(w: float, a: float, b: float, c: float, C: F64) -> None:
    """``C`` <- the matrix of the unit quaternion (w, a, b, c), scalar first."""
    C[0, 0] = 1 - 2 * (b * b + c * c)
    C[0, 1] = 2 * (a * b - w * c)
    C[0, 2] = 2 * (a * c + w * b)
    C[1, 0] = 2 * (a * b + w * c)
    C[1, 1] = 1 - 2 * (a * a + c * c)
    C[1, 2] = 2 * (b * c - w * a)
    C[2, 0] = 2 * (a * c - w * b)
    C[2, 1] = 2 * (b * c + w * a)
    C[2, 2] = 1 - 2 * (a * a + b * b)


@kernel
def qmul(
    p0: float, p1: float, p2: float, p3: float, q0: float, q1: float, q2: float, q3: float
) -> tuple[float, float, float, float]:
    """The Hamilton product p q of two scalar-first quaternions."""
    return (
        p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
        p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
        p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
        p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
    )


@kernel
def rotvec_quat(r0: float, r1: float, r2: float) -> tuple[float, float, float, float]:
    """The scalar-first quaternion of the rotation vector (r0, r1, r2), rad."""
    th = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if th < 1e-9:
        return 1.0 - th * th / 8.0, 0.5 * r0, 0.5 * r1, 0.5 * r2
    s = math.sin(0.5 * th) / th
    return math.cos(0.5 * th), s * r0, s * r1, s * r2


@kernel
def set_quat(x: F64, q0: float, q1: float, q2: float, q3: float) -> None:
    """Store (w, x, y, z) normalised as the state's attitude."""
    n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    x[X_QUAT] = q0 / n
    x[X_QUAT + 1] = q1 / n
    x[X_QUAT + 2] = q2 / n
    x[X_QUAT + 3] = q3 / n


@kernel
def euler_to_quat(roll: float, pitch: float, yaw: float) -> F64:
    """Body->ENU quaternion, scalar first (w, x, y, z), of ``Rz(yaw) Ry(-pitch) Rx(roll)``: FLU
    body, yaw from East, pitch positive nose up, roll positive right side down (the convention
    of :func:`estimator.nav.rotation.dcm_from_euler`)."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(-0.5 * pitch), math.sin(-0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    a = qmul(cy, 0.0, 0.0, sy, cp, 0.0, sp, 0.0)
    b = qmul(a[0], a[1], a[2], a[3], cr, sr, 0.0, 0.0)
    return np.array([b[0], b[1], b[2], b[3]])


@kernel
def dcm_to_euler(C: F64) -> tuple[float, float, float]:
    """Roll, pitch, yaw of a body->ENU matrix (inverse of :func:`euler_to_quat`)."""
    s = C[2, 0]
    s = min(1.0, max(-1.0, s))
    return math.atan2(C[2, 1], C[2, 2]), math.asin(s), math.atan2(C[1, 0], C[0, 0])
