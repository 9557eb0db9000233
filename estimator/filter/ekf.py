"""Strapdown mechanisation and the error-state EKF, compiled with numba.

Everything the filter carries is a plain float64 array, so a run can stop at any IMU sample, be
copied (a checkpoint) and resume bit-identically:

- ``x`` (20): nominal state: position ENU (m), velocity ENU (m/s), attitude quaternion body->ENU
  (w, x, y, z), gyro bias (rad/s), accelerometer bias (m/s^2), wheel-speed scale factor, GNSS
  wander (m, ENU).
- ``P`` (20, 20): covariance of the error state: attitude (a rotation of the ENU frame, rad),
  velocity, position, gyro bias, accelerometer bias, wheel scale, GNSS wander, and the error of
  the lane offset the route pseudo-positions keep (a "consider" state: its correlations are
  tracked, it is never corrected and has no nominal value; see :func:`clone_lane_offset`).
  Errors are ``true - estimate`` and the true attitude is ``(I + [phi x]) C_est``.

The GNSS wander is the slowly varying part of a receiver's error (first-order Gauss-Markov, tens
of seconds): modelled as a state, the filter keeps an honest absolute position variance while
still learning heading and speed from how consecutive fixes move. Treating correlated fixes as
independent makes the position covariance shrink far below the real error.
- ``aux``: the filter's bookkeeping (time, pending covariance propagation, the DR track, the
  previous IMU sample, counters); ``idx``: next IMU / wheel / GNSS sample and output row.

The navigation frame is the fixed local-level ENU frame of the session: gravity is the normal
gravity at the origin along -U, the Earth rate is ``omega_ie * (0, cos lat0, sin lat0)``, and the
velocity equation carries the Coriolis term: the model of :mod:`estimator.nav.earth`.
:func:`run_until` is the whole per-IMU-sample loop (mechanisation, covariance propagation,
wheel/NHC/ZUPT and GNSS updates, output rows), so the Python driver only steps in at the
(low-rate) route-match attempts.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# nominal state
X_POS, X_VEL, X_QUAT, X_BG, X_BA, X_SCALE, X_GW, NX = 0, 3, 6, 10, 13, 16, 17, 20
# error state
E_ATT, E_VEL, E_POS, E_BG, E_BA, E_SCALE, E_GW, E_LANE, NE = 0, 3, 6, 9, 12, 15, 16, 19, 20

# aux: bookkeeping
A_TIME = 0  # time of the state: the last IMU sample processed
A_COV_T = 1  # time accumulated since the last covariance propagation
A_COV_C = 2  # (9) integral of C_bn dt over it
A_COV_F = 11  # (3) integral of C_bn f dt over it
A_DR = 14  # (2) DR track: E, N integrated from the mechanised velocity only
A_DIST = 16  # horizontal distance travelled, m
A_NEXT_OUT = 17  # time of the next regular output row
A_GNSS_USED = 18  # a fix was accepted since the last output row
A_LAST_AID = 19  # time of the last wheel / NHC / ZUPT update
A_PREV_GYRO = 20  # (3) previous IMU sample (for the mid-point integration)
A_PREV_ACCEL = 23  # (3)
A_REJECT_SINCE = 26  # time of the first of the current run of rejected fixes, or -1
A_INFLATE = 27  # 1: widen the position covariance so the next fix is accepted (after pseudo-obs)
A_N_GNSS_USED = 28
A_N_GNSS_REJECTED = 29
A_N_WHEEL = 30
A_N_NHC = 31
A_N_ZUPT = 32
A_N_RESETS = 33
A_STILL_SINCE = 34  # start of the current stationary stretch, or -1
A_GYRO_SUM = 35  # (3) gyro sum over the stationary stretch since the last ZUPT
A_GYRO_N = 38
A_TRUST_T = 40  # time of the last trusted fix
A_CHAIN_T0 = 46  # start of the current run of mutually consistent fixes
A_CHAIN_T = 47  # the run's last fix: time, E, N, DR E, DR N
A_CHAIN_POS = 48  # (2)
A_CHAIN_DR = 50  # (2)
A_N_GNSS_SUSPECT = 52
A_USED_DIST = 53  # A_DIST at the last fix used
NA = 56

# idx
I_IMU, I_WHEEL, I_GNSS, I_OUT, NI = 0, 1, 2, 3, 4

# cfg: constants of one run
C_COV_DT = 0
C_ARW2 = 1  # gyro white noise PSD, rad^2/s
C_VRW2 = 2  # accel white noise PSD, (m/s)^2/s
C_TAU_G = 3
C_QBG = 4  # gyro bias GM driving PSD 2 sigma^2 / tau
C_TAU_A = 5
C_QBA = 6
C_WHEEL_VAR = 7
C_NHC_VAR = 8
C_ZUPT_VAR = 9
C_GNSS_GATE = 10
C_LEVER = 11  # (3) antenna in body FLU
C_GRAVITY = 14
C_WIE = 15  # (3) Earth rate in ENU
C_OUT_DT = 18
C_AID_DT = 19
C_SCALE_ON = 20
C_RESET_S = 21
C_WHEEL_GAP = 22  # wheel samples further apart than this are not interpolated
C_TAU_W = 23  # GNSS wander correlation time
C_QW_H = 24  # GNSS wander driving PSD, horizontal
C_QW_V = 25
C_ROBUST = 26  # test fixes against the dead-reckoned motion
C_WHITE_VAR = 27  # typical white variance of a horizontal fix coordinate
C_WANDER_VAR = 28  # GNSS wander variance, horizontal
NC = 32

PROBATION_GAP_S = 2.0
"""After this long without a trusted fix, new fixes are on probation (see _robust_check)."""
AGREE_S = 3.0
"""Fixes on probation are used once they have agreed with each other for this long."""
IMU_GAP_S = 5.0
"""An IMU interval longer than this (a logging gap) is not integrated: rates held for minutes
turn the attitude into noise. The state is carried across unchanged and the next fix widens
the position covariance to cover wherever the vehicle went meanwhile."""
GAP_VEL_VAR = 5.0**2
GAP_YAW_VAR = (math.pi / 4) ** 2
"""Velocity and yaw variance added across a logging gap: the vehicle may have turned."""
WHEEL_GATE = 25.0
"""Chi-square (1 dof) gate of the wheel-speed row: a slipping or locked wheel disagrees with the
mechanised forward velocity by metres per second, and the position-velocity correlation of a
long outage would turn that into tens of metres of position error per update; the wheel row is
then dropped and the non-holonomic rows still apply."""
ZUPT_MAX_SPEED = 1.0
"""m/s: a stop is only believed when the filter has slowed down to it (a vehicle cruising on a
smooth road at constant speed looks as still to the IMU as a parked one)."""
CHAIN_GAP_S = 1.0
CHAIN_GATE = 9.0
"""Chi-square (2 dof) of the motion between consecutive fixes against the DR motion."""

# output rows
O_T = 0
O_POS = 1
O_VEL = 4
O_RPY = 7
O_SIG_POS = 10
O_SIG_YAW = 13
O_GNSS = 14
O_DR = 15
O_DIST = 17
O_SCALE = 18
O_SIG_SCALE = 19
O_BG = 20
O_BA = 23
NO = 26

STATUS_DONE = 0
STATUS_FULL = 1
STATUS_DIVERGED = 2


# ---------------------------------------------------------------------------------------------
# small rotation helpers


@njit(cache=True, error_model="numpy")
def quat_to_dcm(q: np.ndarray, C: np.ndarray) -> None:
    _dcm(q[0], q[1], q[2], q[3], C)


@njit(cache=True, error_model="numpy")
def _dcm(w, a, b, c, C):
    C[0, 0] = 1 - 2 * (b * b + c * c)
    C[0, 1] = 2 * (a * b - w * c)
    C[0, 2] = 2 * (a * c + w * b)
    C[1, 0] = 2 * (a * b + w * c)
    C[1, 1] = 1 - 2 * (a * a + c * c)
    C[1, 2] = 2 * (b * c - w * a)
    C[2, 0] = 2 * (a * c - w * b)
    C[2, 1] = 2 * (b * c + w * a)
    C[2, 2] = 1 - 2 * (a * a + b * b)


@njit(cache=True, error_model="numpy")
def _qmul(p0, p1, p2, p3, q0, q1, q2, q3):
    return (
        p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
        p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
        p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
        p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
    )


@njit(cache=True, error_model="numpy")
def _rotvec_quat(r0, r1, r2):
    th = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if th < 1e-9:
        return 1.0 - th * th / 8.0, 0.5 * r0, 0.5 * r1, 0.5 * r2
    s = math.sin(0.5 * th) / th
    return math.cos(0.5 * th), s * r0, s * r1, s * r2


@njit(cache=True, error_model="numpy")
def _set_quat(x, q0, q1, q2, q3):
    n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    x[X_QUAT] = q0 / n
    x[X_QUAT + 1] = q1 / n
    x[X_QUAT + 2] = q2 / n
    x[X_QUAT + 3] = q3 / n


@njit(cache=True, error_model="numpy")
def euler_to_quat(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Body->ENU quaternion of ``Rz(yaw) Ry(-pitch) Rx(roll)``: FLU body, yaw from East, pitch
    positive nose up, roll positive right side down (the convention of
    :mod:`estimator.nav.earth`)."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(-0.5 * pitch), math.sin(-0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    a = _qmul(cy, 0.0, 0.0, sy, cp, 0.0, sp, 0.0)
    b = _qmul(a[0], a[1], a[2], a[3], cr, sr, 0.0, 0.0)
    return np.array([b[0], b[1], b[2], b[3]])


@njit(cache=True, error_model="numpy")
def dcm_to_euler(C: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw of a body->ENU matrix (inverse of :func:`euler_to_quat`)."""
    s = C[2, 0]
    s = min(1.0, max(-1.0, s))
    return math.atan2(C[2, 1], C[2, 2]), math.asin(s), math.atan2(C[1, 0], C[0, 0])


# ---------------------------------------------------------------------------------------------
# covariance propagation


@njit(cache=True, error_model="numpy")
def _f_times(M, Cb, fn, w, inv_tau_g, inv_tau_a, inv_tau_w, out):
    """out = F M for the error-state F, using its block sparsity (~50 products per column
    instead of 361)."""
    for c in range(NE):
        a0, a1, a2 = M[0, c], M[1, c], M[2, c]
        v0, v1, v2 = M[3, c], M[4, c], M[5, c]
        g0, g1, g2 = M[9, c], M[10, c], M[11, c]
        b0, b1, b2 = M[12, c], M[13, c], M[14, c]
        # attitude: -w x phi - C dbg
        out[0, c] = -(w[1] * a2 - w[2] * a1) - (Cb[0, 0] * g0 + Cb[0, 1] * g1 + Cb[0, 2] * g2)
        out[1, c] = -(w[2] * a0 - w[0] * a2) - (Cb[1, 0] * g0 + Cb[1, 1] * g1 + Cb[1, 2] * g2)
        out[2, c] = -(w[0] * a1 - w[1] * a0) - (Cb[2, 0] * g0 + Cb[2, 1] * g1 + Cb[2, 2] * g2)
        # velocity: -fn x phi - 2 w x dv - C dba
        out[3, c] = (
            -(fn[1] * a2 - fn[2] * a1)
            - 2 * (w[1] * v2 - w[2] * v1)
            - (Cb[0, 0] * b0 + Cb[0, 1] * b1 + Cb[0, 2] * b2)
        )
        out[4, c] = (
            -(fn[2] * a0 - fn[0] * a2)
            - 2 * (w[2] * v0 - w[0] * v2)
            - (Cb[1, 0] * b0 + Cb[1, 1] * b1 + Cb[1, 2] * b2)
        )
        out[5, c] = (
            -(fn[0] * a1 - fn[1] * a0)
            - 2 * (w[0] * v1 - w[1] * v0)
            - (Cb[2, 0] * b0 + Cb[2, 1] * b1 + Cb[2, 2] * b2)
        )
        out[6, c] = v0
        out[7, c] = v1
        out[8, c] = v2
        out[9, c] = -inv_tau_g * g0
        out[10, c] = -inv_tau_g * g1
        out[11, c] = -inv_tau_g * g2
        out[12, c] = -inv_tau_a * b0
        out[13, c] = -inv_tau_a * b1
        out[14, c] = -inv_tau_a * b2
        out[15, c] = 0.0
        out[16, c] = -inv_tau_w * M[16, c]
        out[17, c] = -inv_tau_w * M[17, c]
        out[18, c] = -inv_tau_w * M[18, c]
        out[19, c] = 0.0


@njit(cache=True, error_model="numpy")
def flush_covariance(P: np.ndarray, aux: np.ndarray, cfg: np.ndarray) -> None:
    """P <- Phi P Phi^T + Q over the time accumulated since the last call, with
    Phi = I + F T and F built from the interval's mean attitude and specific force."""
    _flush(P, aux, cfg, np.empty((NE, NE)), np.empty((NE, NE)), np.empty((3, 3)), np.empty(3))


@njit(cache=True, error_model="numpy")
def _flush(P, aux, cfg, A, B, Cb, fn):
    T = aux[A_COV_T]
    if T <= 0.0:
        return
    for i in range(3):
        for j in range(3):
            Cb[i, j] = aux[A_COV_C + 3 * i + j] / T
    for i in range(3):
        fn[i] = aux[A_COV_F + i] / T
    w = cfg[C_WIE : C_WIE + 3]
    itg = 1.0 / cfg[C_TAU_G]
    ita = 1.0 / cfg[C_TAU_A]
    itw = 1.0 / cfg[C_TAU_W]
    _f_times(P, Cb, fn, w, itg, ita, itw, A)  # A = F P
    _f_times(A.T, Cb, fn, w, itg, ita, itw, B)  # B = F P F^T
    TT = T * T
    for i in range(NE):
        for j in range(i, NE):
            v = P[i, j] + T * (A[i, j] + A[j, i]) + TT * 0.5 * (B[i, j] + B[j, i])
            P[i, j] = v
            P[j, i] = v
    for i in range(3):
        P[E_ATT + i, E_ATT + i] += cfg[C_ARW2] * T
        P[E_VEL + i, E_VEL + i] += cfg[C_VRW2] * T
        P[E_BG + i, E_BG + i] += cfg[C_QBG] * T
        P[E_BA + i, E_BA + i] += cfg[C_QBA] * T
        P[E_GW + i, E_GW + i] += (cfg[C_QW_H] if i < 2 else cfg[C_QW_V]) * T
    aux[A_COV_T] = 0.0
    for i in range(12):
        aux[A_COV_C + i] = 0.0


# ---------------------------------------------------------------------------------------------
# measurement update


@njit(cache=True, error_model="numpy")
def _inv_small(S, m, Si):
    if m == 1:
        Si[0, 0] = 1.0 / S[0, 0]
        return
    if m == 2:
        d = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
        Si[0, 0] = S[1, 1] / d
        Si[1, 1] = S[0, 0] / d
        Si[0, 1] = -S[0, 1] / d
        Si[1, 0] = -S[1, 0] / d
        return
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e, f = S[1, 0], S[1, 1], S[1, 2]
    g, h, k = S[2, 0], S[2, 1], S[2, 2]
    A = e * k - f * h
    B = -(d * k - f * g)
    Cc = d * h - e * g
    det = a * A + b * B + c * Cc
    Si[0, 0] = A / det
    Si[1, 0] = B / det
    Si[2, 0] = Cc / det
    Si[0, 1] = -(b * k - c * h) / det
    Si[1, 1] = (a * k - c * g) / det
    Si[2, 1] = -(a * h - b * g) / det
    Si[0, 2] = (b * f - c * e) / det
    Si[1, 2] = -(a * f - c * d) / det
    Si[2, 2] = (a * e - b * d) / det


@njit(cache=True, error_model="numpy")
def _innovation_cov(P, H, R, m, PHt, S, Si):
    for i in range(NE):
        for a in range(m):
            acc = 0.0
            for j in range(NE):
                h = H[a, j]
                if h != 0.0:
                    acc += P[i, j] * h
            PHt[i, a] = acc
    for a in range(m):
        for b in range(m):
            acc = R[a, b]
            for j in range(NE):
                h = H[a, j]
                if h != 0.0:
                    acc += h * PHt[j, b]
            S[a, b] = acc
    _inv_small(S, m, Si)


@njit(cache=True, error_model="numpy")
def _nis(y, Si, m):
    acc = 0.0
    for a in range(m):
        for b in range(m):
            acc += y[a] * Si[a, b] * y[b]
    return acc


@njit(cache=True, error_model="numpy")
def _apply_update(x, P, y, m, PHt, Si, scale_on):
    """x <- x (+) K y, P <- P - K H P, with K = P H^T S^-1 (the error state is injected into
    the nominal state at once, so it is zero between updates)."""
    K = np.empty((NE, 3))
    dx = np.empty(NE)
    _apply(x, P, y, m, PHt, Si, scale_on, K, dx)


@njit(cache=True, error_model="numpy")
def _apply(x, P, y, m, PHt, Si, scale_on, K, dx):
    # the lane-offset error is considered, not estimated (Schmidt): its gain is zero, and as
    # the last state the symmetric update below then leaves its variance as it was
    for i in range(NE):
        for a in range(m):
            acc = 0.0
            for b in range(m):
                acc += PHt[i, b] * Si[b, a]
            K[i, a] = acc
    for a in range(m):
        K[E_LANE, a] = 0.0
    for i in range(NE):
        for j in range(i, NE):
            acc = 0.0
            for a in range(m):
                acc += K[i, a] * PHt[j, a]
            v = P[i, j] - acc
            P[i, j] = v
            P[j, i] = v
    for i in range(NE):
        acc = 0.0
        for a in range(m):
            acc += K[i, a] * y[a]
        dx[i] = acc
    if not scale_on:
        dx[E_SCALE] = 0.0
    inject(x, dx)


@njit(cache=True, error_model="numpy")
def inject(x: np.ndarray, dx: np.ndarray) -> None:
    """Add an error-state estimate to the nominal state."""
    for i in range(3):
        x[X_POS + i] += dx[E_POS + i]
        x[X_VEL + i] += dx[E_VEL + i]
        x[X_BG + i] += dx[E_BG + i]
        x[X_BA + i] += dx[E_BA + i]
    x[X_SCALE] += dx[E_SCALE]
    for i in range(3):
        x[X_GW + i] += dx[E_GW + i]
    d = _rotvec_quat(dx[0], dx[1], dx[2])
    q = _qmul(d[0], d[1], d[2], d[3], x[X_QUAT], x[X_QUAT + 1], x[X_QUAT + 2], x[X_QUAT + 3])
    _set_quat(x, q[0], q[1], q[2], q[3])


@njit(cache=True, error_model="numpy")
def _body_velocity_update(x, P, cfg, w_speed, use_wheel, C, H, y, R, PHt, S, Si):
    """Wheel speed (forward = scale * wheel) and the non-holonomic constraint (no lateral or
    vertical body velocity) as one observation of the body-frame velocity C^T v. Returns
    whether the wheel row was used (it is gated by :data:`WHEEL_GATE`)."""
    quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
    v0, v1, v2 = x[X_VEL], x[X_VEL + 1], x[X_VEL + 2]
    # vb = C^T v
    vb0 = C[0, 0] * v0 + C[1, 0] * v1 + C[2, 0] * v2
    vb1 = C[0, 1] * v0 + C[1, 1] * v1 + C[2, 1] * v2
    vb2 = C[0, 2] * v0 + C[1, 2] * v1 + C[2, 2] * v2
    if use_wheel:
        # the wheel row alone: h = (c_0 x v, c_0, -w at the scale), innovation variance h P h'
        h = np.zeros(NE)
        c0, c1, c2 = C[0, 0], C[1, 0], C[2, 0]
        h[0] = c1 * v2 - c2 * v1
        h[1] = c2 * v0 - c0 * v2
        h[2] = c0 * v1 - c1 * v0
        h[3], h[4], h[5] = c0, c1, c2
        h[E_SCALE] = -w_speed
        s00 = cfg[C_WHEEL_VAR]
        for i in range(NE):
            if h[i] != 0.0:
                for j in range(NE):
                    s00 += h[i] * P[i, j] * h[j]
        y0 = x[X_SCALE] * w_speed - vb0
        if y0 * y0 > WHEEL_GATE * s00:
            use_wheel = False
    off = 0 if use_wheel else 1
    m = 3 - off
    for a in range(3):
        for j in range(NE):
            H[a, j] = 0.0
        for b in range(3):
            R[a, b] = 0.0
    for a in range(m):
        r = a + off  # body axis
        # d(C^T v) / dphi = C^T [v x]: row r is (c_r x v) with c_r the r-th column of C
        c0, c1, c2 = C[0, r], C[1, r], C[2, r]
        H[a, 0] = c1 * v2 - c2 * v1
        H[a, 1] = c2 * v0 - c0 * v2
        H[a, 2] = c0 * v1 - c1 * v0
        H[a, 3] = c0
        H[a, 4] = c1
        H[a, 5] = c2
        R[a, a] = cfg[C_NHC_VAR]
    if use_wheel:
        H[0, E_SCALE] = -w_speed
        R[0, 0] = cfg[C_WHEEL_VAR]
        y[0] = x[X_SCALE] * w_speed - vb0
        y[1] = -vb1
        y[2] = -vb2
    else:
        y[0] = -vb1
        y[1] = -vb2
    _innovation_cov(P, H, R, m, PHt, S, Si)
    _apply_update(x, P, y, m, PHt, Si, cfg[C_SCALE_ON] > 0)
    return use_wheel


@njit(cache=True, error_model="numpy")
def _zupt_update(x, P, aux, cfg, H, y, R, PHt, S, Si):
    """Zero velocity, and zero angular rate (the mean gyro while still measures its bias plus
    the Earth rate)."""
    for a in range(3):
        for j in range(NE):
            H[a, j] = 0.0
        for b in range(3):
            R[a, b] = 0.0
        H[a, E_VEL + a] = 1.0
        R[a, a] = cfg[C_ZUPT_VAR]
        y[a] = -x[X_VEL + a]
    _innovation_cov(P, H, R, 3, PHt, S, Si)
    _apply_update(x, P, y, 3, PHt, Si, cfg[C_SCALE_ON] > 0)
    n = aux[A_GYRO_N]
    if n >= 2:
        C = np.empty((3, 3))
        quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
        w = cfg[C_WIE : C_WIE + 3]
        var = cfg[C_ARW2] / max(cfg[C_AID_DT], 1e-3) + (1e-5) ** 2
        for a in range(3):
            for j in range(NE):
                H[a, j] = 0.0
            for b in range(3):
                R[a, b] = 0.0
            H[a, E_BG + a] = 1.0
            R[a, a] = var
            wb = C[0, a] * w[0] + C[1, a] * w[1] + C[2, a] * w[2]
            y[a] = aux[A_GYRO_SUM + a] / n - x[X_BG + a] - wb
        _innovation_cov(P, H, R, 3, PHt, S, Si)
        _apply_update(x, P, y, 3, PHt, Si, cfg[C_SCALE_ON] > 0)
    aux[A_GYRO_N] = 0.0
    for a in range(3):
        aux[A_GYRO_SUM + a] = 0.0


@njit(cache=True, error_model="numpy")
def _widen_position(P, y, S):
    """Add diag(max(0, y_i^2 - S_ii)) to the E/N position variance: the fix then agrees with
    the filter to about one sigma and is accepted, and P stays positive definite."""
    for a in range(2):
        d = y[a] * y[a] - S[a, a]
        if d > 0.0:
            P[E_POS + a, E_POS + a] += d


@njit(cache=True, error_model="numpy")
def _widen_heading(x, P, y, aux):
    """Widen yaw and horizontal velocity variance by the heading error that explains the fix's
    horizontal innovation over the distance driven since the last fix used (a heading error
    grown linearly over D puts the vehicle about theta * D / 2 off). Widening only the position
    would leave a filter that claims a tenth of a degree of yaw with a heading ten degrees off:
    each later fix then pulls the position back and the heading drags it away again."""
    dist = aux[A_DIST] - aux[A_USED_DIST]
    if dist < 1.0:
        return
    theta = min(2.0 * math.hypot(y[0], y[1]) / dist, math.pi / 4)
    var_yaw = theta * theta
    if var_yaw <= P[E_ATT + 2, E_ATT + 2]:
        return
    P[E_ATT + 2, E_ATT + 2] += var_yaw
    speed2 = x[X_VEL] * x[X_VEL] + x[X_VEL + 1] * x[X_VEL + 1]
    for a in range(2):
        P[E_VEL + a, E_VEL + a] += speed2 * var_yaw


@njit(cache=True, error_model="numpy")
def _robust_check(aux, cfg, t_fix, e, n, dr_e, dr_n, nis_typical):
    """Robust GNSS: is a fix trusted? Returns 0 (use it as it is), 1 (it disagrees with the
    filter: inflate its covariance by its innovation) or -1 (on probation: do not use it).

    ``nis_typical`` is the horizontal innovation tested against the filter's covariance plus
    the *typical* white variance of the log's fixes, not the variance the fix reports: at tunnel
    portals receivers report metre-level sigmas for jumps of 5-15 m. Fixes are also chained by
    the distance dead reckoning drove between consecutive fixes (good to centimetres over a
    fraction of a second, and blind to the heading error DR may have gathered in a long outage,
    which would otherwise make every returning fix 'disagree'): after a gap of more than
    PROBATION_GAP_S (an outage) fixes are not used until they have agreed with each other for
    AGREE_S, and a chain that agrees that long is trusted even if it disagrees with the filter
    (then the filter was wrong)."""
    ct = aux[A_CHAIN_T]
    chain_ok = False
    if ct > 0 and t_fix - ct <= CHAIN_GAP_S:
        step_fix = math.hypot(e - aux[A_CHAIN_POS], n - aux[A_CHAIN_POS + 1])
        step_dr = math.hypot(dr_e - aux[A_CHAIN_DR], dr_n - aux[A_CHAIN_DR + 1])
        d = step_fix - step_dr
        chain_ok = d * d / (2.0 * cfg[C_WHITE_VAR]) <= CHAIN_GATE
    if not chain_ok:
        aux[A_CHAIN_T0] = t_fix
    aux[A_CHAIN_T] = t_fix
    aux[A_CHAIN_POS], aux[A_CHAIN_POS + 1] = e, n
    aux[A_CHAIN_DR], aux[A_CHAIN_DR + 1] = dr_e, dr_n
    chain_long = t_fix - aux[A_CHAIN_T0] >= AGREE_S
    probation = t_fix - aux[A_TRUST_T] > PROBATION_GAP_S
    if chain_long or (not probation and nis_typical <= cfg[C_GNSS_GATE]):
        aux[A_TRUST_T] = t_fix
        return 0
    aux[A_N_GNSS_SUSPECT] += 1
    return -1 if probation else 1


@njit(cache=True, error_model="numpy")
def _gnss_update(x, P, aux, cfg, t, t_fix, pos, var, C, H, y, R, PHt, S, Si):
    """One fix: antenna lever arm, the fix moved to the state time with the velocity, the
    motion check (robust GNSS), separate chi-square gates on horizontal and vertical
    innovations. Returns 1 if the fix was used."""
    dtf = t - t_fix
    quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
    lv = cfg[C_LEVER : C_LEVER + 3]
    la = np.empty(3)
    for i in range(3):
        la[i] = C[i, 0] * lv[0] + C[i, 1] * lv[1] + C[i, 2] * lv[2]
    for a in range(3):
        for j in range(NE):
            H[a, j] = 0.0
        for b in range(3):
            R[a, b] = 0.0
        H[a, E_POS + a] = 1.0
        H[a, E_GW + a] = 1.0
        R[a, a] = var[a]
        y[a] = pos[a] - (x[X_POS + a] - x[X_VEL + a] * dtf + la[a] + x[X_GW + a])
    # d(C l)/dphi = -[C l x]
    H[0, 1] = la[2]
    H[0, 2] = -la[1]
    H[1, 0] = -la[2]
    H[1, 2] = la[0]
    H[2, 0] = la[1]
    H[2, 1] = -la[0]
    if cfg[C_ROBUST] > 0:
        R[0, 0] = R[1, 1] = cfg[C_WHITE_VAR]
        _innovation_cov(P, H, R, 2, PHt, S, Si)
        nis_typical = _nis(y, Si, 2)
        R[0, 0], R[1, 1] = var[0], var[1]
        # the antenna on the DR track at the fix time
        dr_e = aux[A_DR] - x[X_VEL] * dtf + la[0]
        dr_n = aux[A_DR + 1] - x[X_VEL + 1] * dtf + la[1]
        verdict = _robust_check(aux, cfg, t_fix, pos[0], pos[1], dr_e, dr_n, nis_typical)
        if verdict < 0:
            return 0
        if verdict > 0:
            R[0, 0] += y[0] * y[0]
            R[1, 1] += y[1] * y[1]
    _innovation_cov(P, H, R, 3, PHt, S, Si)
    gate = cfg[C_GNSS_GATE]
    widen = aux[A_INFLATE] > 0
    if not widen and aux[A_REJECT_SINCE] >= 0 and t - aux[A_REJECT_SINCE] > cfg[C_RESET_S]:
        widen = True
    if widen:
        _widen_heading(x, P, y, aux)
        _widen_position(P, y, S)
        _innovation_cov(P, H, R, 3, PHt, S, Si)
        aux[A_INFLATE] = 0.0
        aux[A_N_RESETS] += 1
    d = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    nis_h = (S[1, 1] * y[0] * y[0] - 2 * S[0, 1] * y[0] * y[1] + S[0, 0] * y[1] * y[1]) / d
    if nis_h > gate:
        if aux[A_REJECT_SINCE] < 0:
            aux[A_REJECT_SINCE] = t
        aux[A_N_GNSS_REJECTED] += 1
        return 0
    aux[A_REJECT_SINCE] = -1.0
    m = 3
    if y[2] * y[2] / S[2, 2] > gate:
        m = 2
        _innovation_cov(P, H, R, 2, PHt, S, Si)
    _apply_update(x, P, y, m, PHt, Si, cfg[C_SCALE_ON] > 0)
    aux[A_N_GNSS_USED] += 1
    aux[A_USED_DIST] = aux[A_DIST]
    return 1


@njit(cache=True, error_model="numpy")
def pseudo_position_update(
    x: np.ndarray,
    P: np.ndarray,
    aux: np.ndarray,
    cfg: np.ndarray,
    z: np.ndarray,
    R2: np.ndarray,
    normal: np.ndarray,
) -> np.ndarray:
    """The route pseudo-observation of E, N position with covariance ``R2``. Returns
    [innovation E, N, correction E, N]. Also asks the next GNSS fix to widen the position
    covariance (see :func:`_widen_position`).

    The truth is ``z + normal * (lane-offset error) + noise`` (``normal``: the route's left
    normal at the match; zero leaves the lane-offset error out)."""
    flush_covariance(P, aux, cfg)
    H = np.zeros((3, NE))
    R = np.zeros((3, 3))
    y = np.zeros(3)
    PHt = np.empty((NE, 3))
    S = np.empty((3, 3))
    Si = np.empty((3, 3))
    for a in range(2):
        H[a, E_POS + a] = 1.0
        H[a, E_LANE] = -normal[a]
        y[a] = z[a] - x[X_POS + a]
        for b in range(2):
            R[a, b] = R2[a, b]
    p0, p1 = x[X_POS], x[X_POS + 1]
    _innovation_cov(P, H, R, 2, PHt, S, Si)
    _apply_update(x, P, y, 2, PHt, Si, cfg[C_SCALE_ON] > 0)
    aux[A_INFLATE] = 1.0
    return np.array([y[0], y[1], x[X_POS] - p0, x[X_POS + 1] - p1])


@njit(cache=True, error_model="numpy")
def clone_lane_offset(P: np.ndarray, aux: np.ndarray, cfg: np.ndarray, normal: np.ndarray) -> None:
    """Start an outage's lane-offset error as a clone of the cross-track position error.

    The lane offset every pseudo-position of an outage keeps was learned from the estimate while
    GNSS was good, so it is wrong by the estimate's own cross-track error then (mostly the
    receiver's slow wander), and all the outage's matches share that error. Treated as
    independent noise it must either get a metre-level sigma, with which the estimate lags the
    route, or it makes the position covariance shrink far below the real error. Carried as a
    state correlated one-to-one with the position error at the outage start, consecutive
    matches hold the estimate to the route while the absolute cross-track variance stays what
    GNSS left. ``normal``: the route's left normal at the vehicle."""
    flush_covariance(P, aux, cfg)
    for j in range(NE):
        v = normal[0] * P[E_POS, j] + normal[1] * P[E_POS + 1, j]
        P[E_LANE, j] = v
        P[j, E_LANE] = v
    P[E_LANE, E_LANE] = normal[0] * P[E_LANE, E_POS] + normal[1] * P[E_LANE, E_POS + 1]


@njit(cache=True, error_model="numpy")
def heading_update(
    x: np.ndarray, P: np.ndarray, aux: np.ndarray, cfg: np.ndarray, dyaw: float, var: float
) -> float:
    """A yaw observation: the true yaw is the estimate plus ``dyaw`` (rad) with variance
    ``var``. Returns the yaw change applied."""
    flush_covariance(P, aux, cfg)
    H = np.zeros((3, NE))
    R = np.zeros((3, 3))
    y = np.zeros(3)
    PHt = np.empty((NE, 3))
    S = np.empty((3, 3))
    Si = np.empty((3, 3))
    H[0, E_ATT + 2] = 1.0
    R[0, 0] = var
    y[0] = dyaw
    C = np.empty((3, 3))
    quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
    yaw0 = dcm_to_euler(C)[2]
    _innovation_cov(P, H, R, 1, PHt, S, Si)
    _apply_update(x, P, y, 1, PHt, Si, cfg[C_SCALE_ON] > 0)
    quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
    d = dcm_to_euler(C)[2] - yaw0
    return math.atan2(math.sin(d), math.cos(d))


# ---------------------------------------------------------------------------------------------
# the loop


@njit(cache=True, error_model="numpy")
def write_row(
    x: np.ndarray, P: np.ndarray, aux: np.ndarray, idx: np.ndarray, out: np.ndarray
) -> None:
    """Write the current state as an output row; a row at the same time as the previous one
    replaces it (a match attempt at a regular output instant)."""
    r = idx[I_OUT]
    used = aux[A_GNSS_USED]
    if r > 0 and out[r - 1, O_T] == aux[A_TIME]:
        r -= 1
        used = max(used, out[r, O_GNSS])
    else:
        idx[I_OUT] = r + 1
    C = np.empty((3, 3))
    quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
    roll, pitch, yaw = dcm_to_euler(C)
    out[r, O_T] = aux[A_TIME]
    for i in range(3):
        out[r, O_POS + i] = x[X_POS + i]
        out[r, O_VEL + i] = x[X_VEL + i]
        out[r, O_SIG_POS + i] = math.sqrt(max(P[E_POS + i, E_POS + i], 0.0))
        out[r, O_BG + i] = x[X_BG + i]
        out[r, O_BA + i] = x[X_BA + i]
    out[r, O_RPY] = roll
    out[r, O_RPY + 1] = pitch
    out[r, O_RPY + 2] = yaw
    out[r, O_SIG_YAW] = math.sqrt(max(P[E_ATT + 2, E_ATT + 2], 0.0))
    out[r, O_GNSS] = used
    out[r, O_DR] = aux[A_DR]
    out[r, O_DR + 1] = aux[A_DR + 1]
    out[r, O_DIST] = aux[A_DIST]
    out[r, O_SCALE] = x[X_SCALE]
    out[r, O_SIG_SCALE] = math.sqrt(max(P[E_SCALE, E_SCALE], 0.0))
    aux[A_GNSS_USED] = 0.0


@njit(cache=True, error_model="numpy")
def _finite(x, P):
    acc = 0.0
    for i in range(NX):
        acc += x[i]
    for i in range(NE):
        acc += P[i, i]
    return math.isfinite(acc)


@njit(cache=True, error_model="numpy")
def run_until(
    t_stop: float,
    x: np.ndarray,
    P: np.ndarray,
    aux: np.ndarray,
    idx: np.ndarray,
    imu_t: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    still: np.ndarray,
    wheel_t: np.ndarray,
    wheel_v: np.ndarray,
    gnss_t: np.ndarray,
    gnss_pos: np.ndarray,
    gnss_var: np.ndarray,
    cfg: np.ndarray,
    out: np.ndarray,
) -> int:
    """Process IMU samples (and the measurements up to each of them) while their time is
    <= ``t_stop``. Returns STATUS_DONE, STATUS_FULL (``out`` has no room: grow it and call
    again) or STATUS_DIVERGED. Stopping and resuming does not change any result."""
    n = imu_t.shape[0]
    nw = wheel_t.shape[0]
    ng = gnss_t.shape[0]
    C = np.empty((3, 3))
    H = np.zeros((3, NE))
    R = np.zeros((3, 3))
    y = np.zeros(3)
    PHt = np.empty((NE, 3))
    S = np.empty((3, 3))
    Si = np.empty((3, 3))
    FA = np.empty((NE, NE))
    FB = np.empty((NE, NE))
    FC = np.empty((3, 3))
    FF = np.empty(3)
    w = cfg[C_WIE : C_WIE + 3]
    grav = cfg[C_GRAVITY]
    itw = 1.0 / cfg[C_TAU_W]
    while idx[I_IMU] < n:
        k = idx[I_IMU]
        t = imu_t[k]
        if t > t_stop:
            return STATUS_DONE
        if idx[I_OUT] >= out.shape[0] - 2:
            return STATUS_FULL
        dt = t - aux[A_TIME]
        if dt > IMU_GAP_S:
            dt = 0.0
            aux[A_INFLATE] = 1.0
            for i in range(3):
                P[E_VEL + i, E_VEL + i] += GAP_VEL_VAR
            P[E_ATT + 2, E_ATT + 2] += GAP_YAW_VAR
        # --- mechanisation: mid-point rates, velocity with the mid-interval attitude
        wm0 = 0.5 * (aux[A_PREV_GYRO] + gyro[k, 0]) - x[X_BG]
        wm1 = 0.5 * (aux[A_PREV_GYRO + 1] + gyro[k, 1]) - x[X_BG + 1]
        wm2 = 0.5 * (aux[A_PREV_GYRO + 2] + gyro[k, 2]) - x[X_BG + 2]
        fm0 = 0.5 * (aux[A_PREV_ACCEL] + accel[k, 0]) - x[X_BA]
        fm1 = 0.5 * (aux[A_PREV_ACCEL + 1] + accel[k, 1]) - x[X_BA + 1]
        fm2 = 0.5 * (aux[A_PREV_ACCEL + 2] + accel[k, 2]) - x[X_BA + 2]
        q0, q1, q2, q3 = x[X_QUAT], x[X_QUAT + 1], x[X_QUAT + 2], x[X_QUAT + 3]
        h = _rotvec_quat(0.5 * dt * wm0, 0.5 * dt * wm1, 0.5 * dt * wm2)
        e = _rotvec_quat(-0.5 * dt * w[0], -0.5 * dt * w[1], -0.5 * dt * w[2])
        qm = _qmul(q0, q1, q2, q3, h[0], h[1], h[2], h[3])
        qm = _qmul(e[0], e[1], e[2], e[3], qm[0], qm[1], qm[2], qm[3])
        _dcm(qm[0], qm[1], qm[2], qm[3], C)
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
        b = _rotvec_quat(dt * wm0, dt * wm1, dt * wm2)
        ee = _rotvec_quat(-dt * w[0], -dt * w[1], -dt * w[2])
        qn = _qmul(q0, q1, q2, q3, b[0], b[1], b[2], b[3])
        qn = _qmul(ee[0], ee[1], ee[2], ee[3], qn[0], qn[1], qn[2], qn[3])
        _set_quat(x, qn[0], qn[1], qn[2], qn[3])
        decay = 1.0 - dt * itw
        x[X_GW] *= decay
        x[X_GW + 1] *= decay
        x[X_GW + 2] *= decay
        de = 0.5 * (v0 + n0) * dt
        dn = 0.5 * (v1 + n1) * dt
        aux[A_DR] += de
        aux[A_DR + 1] += dn
        aux[A_DIST] += math.sqrt(de * de + dn * dn)
        # --- pending covariance propagation
        aux[A_COV_T] += dt
        for i in range(3):
            for j in range(3):
                aux[A_COV_C + 3 * i + j] += C[i, j] * dt
        aux[A_COV_F] += fn0 * dt
        aux[A_COV_F + 1] += fn1 * dt
        aux[A_COV_F + 2] += fn2 * dt
        if aux[A_COV_T] >= cfg[C_COV_DT]:
            _flush(P, aux, cfg, FA, FB, FC, FF)
        aux[A_TIME] = t
        aux[A_PREV_GYRO], aux[A_PREV_GYRO + 1], aux[A_PREV_GYRO + 2] = (
            gyro[k, 0],
            gyro[k, 1],
            gyro[k, 2],
        )
        aux[A_PREV_ACCEL], aux[A_PREV_ACCEL + 1], aux[A_PREV_ACCEL + 2] = (
            accel[k, 0],
            accel[k, 1],
            accel[k, 2],
        )
        # --- wheel speed / NHC / ZUPT at the aid rate
        while idx[I_WHEEL] < nw and wheel_t[idx[I_WHEEL]] <= t:
            idx[I_WHEEL] += 1
        if still[k]:
            for i in range(3):
                aux[A_GYRO_SUM + i] += gyro[k, i]
            aux[A_GYRO_N] += 1
        else:
            aux[A_GYRO_N] = 0.0
            for i in range(3):
                aux[A_GYRO_SUM + i] = 0.0
        if t - aux[A_LAST_AID] >= cfg[C_AID_DT] - 1e-9:
            aux[A_LAST_AID] = t
            _flush(P, aux, cfg, FA, FB, FC, FF)
            speed2 = x[X_VEL] * x[X_VEL] + x[X_VEL + 1] * x[X_VEL + 1] + x[X_VEL + 2] * x[X_VEL + 2]
            if still[k] and speed2 < ZUPT_MAX_SPEED * ZUPT_MAX_SPEED:
                _zupt_update(x, P, aux, cfg, H, y, R, PHt, S, Si)
                aux[A_N_ZUPT] += 1
            else:
                j = idx[I_WHEEL]
                have = j > 0 and j < nw and wheel_t[j] - wheel_t[j - 1] <= cfg[C_WHEEL_GAP]
                ws = 0.0
                if have:
                    f = (t - wheel_t[j - 1]) / (wheel_t[j] - wheel_t[j - 1])
                    ws = wheel_v[j - 1] + f * (wheel_v[j] - wheel_v[j - 1])
                elif j > 0 and j == nw and t - wheel_t[j - 1] <= 0.5 * cfg[C_WHEEL_GAP]:
                    have = True
                    ws = wheel_v[j - 1]
                if _body_velocity_update(x, P, cfg, ws, have, C, H, y, R, PHt, S, Si):
                    aux[A_N_WHEEL] += 1
                else:
                    aux[A_N_NHC] += 1
        # --- GNSS
        while idx[I_GNSS] < ng and gnss_t[idx[I_GNSS]] <= t:
            g = idx[I_GNSS]
            idx[I_GNSS] += 1
            _flush(P, aux, cfg, FA, FB, FC, FF)
            used = _gnss_update(
                x, P, aux, cfg, t, gnss_t[g], gnss_pos[g], gnss_var[g], C, H, y, R, PHt, S, Si
            )
            if used:
                aux[A_GNSS_USED] = 1.0
        idx[I_IMU] = k + 1
        if t >= aux[A_NEXT_OUT]:
            if not _finite(x, P):
                return STATUS_DIVERGED
            write_row(x, P, aux, idx, out)
            while aux[A_NEXT_OUT] <= t:
                aux[A_NEXT_OUT] += cfg[C_OUT_DT]
    return STATUS_DONE
