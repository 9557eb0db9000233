"""Strapdown mechanisation in the session's fixed local-level ENU frame (as KF-GINS' ``insmech``):
gravity is the normal gravity at the origin along -U, the Earth rate is
``omega_ie * (0, cos lat0, sin lat0)``, and the velocity equation carries the Coriolis term (the
model of :mod:`estimator.nav.earth`). Pure state propagation: no covariance, no measurement."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from estimator.filter.compiled import kernel
from estimator.filter.layout import (
    A_DIST,
    A_DR,
    A_PREV_ACCEL,
    A_PREV_GYRO,
    X_BA,
    X_BG,
    X_GSF,
    X_GW,
    X_POS,
    X_QUAT,
    X_VEL,
)
from estimator.filter.quaternion import dcm_of, qmul, rotvec_quat, set_quat

F64 = NDArray[np.float64]


@kernel
def mechanise(
    x: F64,
    aux: F64,
    gyro: F64,
    accel: F64,
    k: int,
    dt: float,
    w: F64,
    grav: float,
    inv_tau_w: float,
    C: F64,
) -> tuple[float, float, float, float]:
    """Advance the nominal state by ``dt`` to IMU sample ``k``: mid-point rates (the previous
    sample is in ``aux``), velocity with the mid-interval attitude, trapezoidal position, the
    GNSS wander's decay, and the DR track and distance (from the mechanised velocity only).
    Leaves the mid-interval body->ENU matrix in ``C`` and returns the specific force in ENU and
    the body z rate (all for the covariance propagation). The z rate is divided by ``1 +
    X_GSF`` (zero unless extensions.gyro_scale_state estimates the z gyro's scale factor)."""
    wm0 = 0.5 * (aux[A_PREV_GYRO] + gyro[k, 0]) - x[X_BG]
    wm1 = 0.5 * (aux[A_PREV_GYRO + 1] + gyro[k, 1]) - x[X_BG + 1]
    wm2 = (0.5 * (aux[A_PREV_GYRO + 2] + gyro[k, 2]) - x[X_BG + 2]) / (1.0 + x[X_GSF])
    fm0 = 0.5 * (aux[A_PREV_ACCEL] + accel[k, 0]) - x[X_BA]
    fm1 = 0.5 * (aux[A_PREV_ACCEL + 1] + accel[k, 1]) - x[X_BA + 1]
    fm2 = 0.5 * (aux[A_PREV_ACCEL + 2] + accel[k, 2]) - x[X_BA + 2]
    q0, q1, q2, q3 = x[X_QUAT], x[X_QUAT + 1], x[X_QUAT + 2], x[X_QUAT + 3]
    h = rotvec_quat(0.5 * dt * wm0, 0.5 * dt * wm1, 0.5 * dt * wm2)
    e = rotvec_quat(-0.5 * dt * w[0], -0.5 * dt * w[1], -0.5 * dt * w[2])
    qm = qmul(q0, q1, q2, q3, h[0], h[1], h[2], h[3])
    qm = qmul(e[0], e[1], e[2], e[3], qm[0], qm[1], qm[2], qm[3])
    dcm_of(qm[0], qm[1], qm[2], qm[3], C)
    fn0 = C[0, 0] * fm0 + C[0, 1] * fm1 + C[0, 2] * fm2
    fn1 = C[1, 0] * fm0 + C[1, 1] * fm1 + C[1, 2] * fm2
    fn2 = C[2, 0] * fm0 + C[2, 1] * fm1 + C[2, 2] * fm2
    v0, v1, v2 = x[X_VEL], x[X_VEL + 1], x[X_VEL + 2]
    a0 = fn0 - 2 * (w[1] * v2 - w[2] * v1)
    a1 = fn1 - 2 * (w[2] * v0 - w[0] * v2)
    a2 = fn2 - 2 * (w[0] * v1 - w[1] * v0) - grav
    n0, n1, n2 = v0 + a0 * dt, v1 + a1 * dt, v2 + a2 * dt
    x[X_POS] += 0.5 * (v0 + n0) * dt
    x[X_POS + 1] += 0.5 * (v1 + n1) * dt
    x[X_POS + 2] += 0.5 * (v2 + n2) * dt
    x[X_VEL], x[X_VEL + 1], x[X_VEL + 2] = n0, n1, n2
    b = rotvec_quat(dt * wm0, dt * wm1, dt * wm2)
    ee = rotvec_quat(-dt * w[0], -dt * w[1], -dt * w[2])
    qn = qmul(q0, q1, q2, q3, b[0], b[1], b[2], b[3])
    qn = qmul(ee[0], ee[1], ee[2], ee[3], qn[0], qn[1], qn[2], qn[3])
    set_quat(x, qn[0], qn[1], qn[2], qn[3])
    decay = 1.0 - dt * inv_tau_w
    x[X_GW] *= decay
    x[X_GW + 1] *= decay
    x[X_GW + 2] *= decay
    de = 0.5 * (v0 + n0) * dt
    dn = 0.5 * (v1 + n1) * dt
    aux[A_DR] += de
    aux[A_DR + 1] += dn
    aux[A_DIST] += math.sqrt(de * de + dn * dn)
    return fn0, fn1, fn2, wm2
