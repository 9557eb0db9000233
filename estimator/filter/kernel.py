"""The compiled filter loop: per IMU sample, mechanisation, covariance propagation, the
wheel / NHC / ZUPT updates at the aid rate, the GNSS fixes up to the sample, and output rows.
The Python driver only steps in at the (low-rate) route-match attempts; the loop stops at any
time and resumes bit-identically, since everything it carries is in plain arrays
(:mod:`estimator.filter.layout`)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from estimator.filter.compiled import kernel
from estimator.filter.gnss import gnss_update
from estimator.filter.layout import (
    A_COV_T,
    A_DIST,
    A_DR,
    A_GNSS_USED,
    A_GYRO_N,
    A_GYRO_SUM,
    A_INFLATE,
    A_LAST_AID,
    A_NEXT_OUT,
    A_POS_WALK,
    A_PREV_ACCEL,
    A_PREV_GYRO,
    A_TIME,
    A_WALK_FROM,
    C_AID_DT,
    C_COV_DT,
    C_GRAVITY,
    C_OUT_DT,
    C_TAU_W,
    C_WHEEL_GAP,
    C_WIE,
    E_ATT,
    E_POS,
    E_VEL,
    I_GNSS,
    I_IMU,
    I_OUT,
    I_WHEEL,
    NE,
    NX,
    O_COV_EN,
    O_DIST,
    O_DR,
    O_GNSS,
    O_POS,
    O_RPY,
    O_SIG_POS,
    O_SIG_YAW,
    O_T,
    O_VEL,
    STATUS_DIVERGED,
    STATUS_DONE,
    STATUS_FULL,
    X_POS,
    X_QUAT,
    X_SCALE,
    X_VEL,
)
from estimator.filter.mechanisation import mechanise
from estimator.filter.propagation import accumulate, flush_into
from estimator.filter.quaternion import dcm_to_euler, quat_to_dcm
from estimator.filter.updates import body_velocity_update, zupt_update

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

IMU_GAP_S = 5.0
"""An IMU interval longer than this (a logging gap) is not integrated: rates held for minutes
turn the attitude into noise. Where the wheel speed covers the gap, the position is carried
along the last heading by the distance the wheels measured (:func:`_bridge`; on a log without
wheel speed, by the last velocity); the next fix widens the position covariance to cover
wherever the vehicle went meanwhile."""
GAP_VEL_VAR = 5.0**2
GAP_YAW_VAR = (math.pi / 4) ** 2
"""Velocity and yaw variance added across a logging gap: the vehicle may have turned."""
GAP_TILT_VAR = math.radians(3.0) ** 2
"""Roll and pitch variance added across a logging gap: the road's grade and bank change (3 deg
is a 5 % grade). Held at the sigma before the gap, a grade the gap hides leaks gravity into the
forward acceleration (0.17 m/s^2 a degree), which the wheel-speed row then reads as heading."""
OUTPUT_STEPS_WALKED = 1_000_000
"""Output intervals the next output time is stepped through one by one (14 h at 20 Hz); a
longer gap is crossed in one step (:func:`_next_output_after`)."""
ZUPT_MAX_SPEED = 1.0
"""m/s: a stop is only believed when the filter has slowed down to it (a vehicle cruising on a
smooth road at constant speed looks as still to the IMU as a parked one)."""


@kernel
def write_row(x: F64, P: F64, aux: F64, idx: I64, out: F64) -> None:
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
    out[r, O_RPY] = roll
    out[r, O_RPY + 1] = pitch
    out[r, O_RPY + 2] = yaw
    out[r, O_SIG_YAW] = math.sqrt(max(P[E_ATT + 2, E_ATT + 2], 0.0))
    out[r, O_COV_EN] = P[E_POS, E_POS + 1]
    out[r, O_GNSS] = used
    out[r, O_DR] = aux[A_DR]
    out[r, O_DR + 1] = aux[A_DR + 1]
    out[r, O_DIST] = aux[A_DIST]
    aux[A_GNSS_USED] = 0.0


@kernel
def finite_state(x: F64, P: F64) -> bool:
    """Whether the state and the covariance diagonal are finite (one sum: NaN and inf spread)."""
    acc = 0.0
    for i in range(NX):
        acc += x[i]
    for i in range(NE):
        acc += P[i, i]
    return math.isfinite(acc)


@kernel
def run_until(
    t_stop: float,
    x: F64,
    P: F64,
    aux: F64,
    idx: I64,
    imu_t: F64,
    gyro: F64,
    accel: F64,
    still: NDArray[np.bool_],
    wheel_t: F64,
    wheel_v: F64,
    gnss_t: F64,
    gnss_pos: F64,
    gnss_var: F64,
    cfg: F64,
    out: F64,
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
        dt = _interval(P, aux, t)
        if dt == 0.0 and aux[A_INFLATE] > 0 and t - aux[A_TIME] > IMU_GAP_S:
            _bridge(x, P, aux, t, wheel_t, wheel_v)
        # --- strapdown, and the pending covariance propagation
        fn0, fn1, fn2, wz = mechanise(x, aux, gyro, accel, k, dt, w, grav, itw, C)
        accumulate(aux, C, fn0, fn1, fn2, wz, dt)
        if aux[A_COV_T] >= cfg[C_COV_DT]:
            flush_into(P, aux, cfg, FA, FB, FC, FF)
        _hold_sample(aux, t, gyro, accel, k)
        # --- wheel speed / NHC / ZUPT at the aid rate (the NHC's variance grows with the speed
        # by noise.nhc_mount_sigma_deg; this file's compiled cache holds body_velocity_update
        # inlined, and numba re-compiles it only when this file changes)
        while idx[I_WHEEL] < nw and wheel_t[idx[I_WHEEL]] <= t:
            idx[I_WHEEL] += 1
        _gather_still_gyro(aux, gyro, k, still[k])
        if t - aux[A_LAST_AID] >= cfg[C_AID_DT] - 1e-9:
            aux[A_LAST_AID] = t
            flush_into(P, aux, cfg, FA, FB, FC, FF)
            speed2 = x[X_VEL] * x[X_VEL] + x[X_VEL + 1] * x[X_VEL + 1] + x[X_VEL + 2] * x[X_VEL + 2]
            if still[k] and speed2 < ZUPT_MAX_SPEED * ZUPT_MAX_SPEED:
                zupt_update(x, P, aux, cfg, H, y, R, PHt, S, Si)
            else:
                have, ws = _wheel_speed(t, idx[I_WHEEL], wheel_t, wheel_v, cfg[C_WHEEL_GAP])
                body_velocity_update(x, P, cfg, ws, have, C, H, y, R, PHt, S, Si)
        # --- GNSS
        while idx[I_GNSS] < ng and gnss_t[idx[I_GNSS]] <= t:
            g = idx[I_GNSS]
            idx[I_GNSS] += 1
            flush_into(P, aux, cfg, FA, FB, FC, FF)
            used = gnss_update(
                x, P, aux, cfg, t, gnss_t[g], gnss_pos[g], gnss_var[g], C, H, y, R, PHt, S, Si
            )
            if used:
                aux[A_GNSS_USED] = 1.0
                if gnss_t[g] > aux[A_WALK_FROM]:
                    aux[A_POS_WALK] = 0.0
        idx[I_IMU] = k + 1
        if t >= aux[A_NEXT_OUT]:
            if not finite_state(x, P):
                return STATUS_DIVERGED
            write_row(x, P, aux, idx, out)
            _next_output_after(aux, t, cfg[C_OUT_DT])
    return STATUS_DONE


@kernel
def _next_output_after(aux: F64, t: float, out_dt: float) -> None:
    """Move the next output time past ``t`` on the output grid. Across a gap of more than
    :data:`OUTPUT_STEPS_WALKED` intervals (a clock that jumped days or years forward) the grid
    is crossed in one step: walked, it would take a loop iteration per output interval."""
    behind = t - aux[A_NEXT_OUT]
    if behind > OUTPUT_STEPS_WALKED * out_dt:
        aux[A_NEXT_OUT] += (math.floor(behind / out_dt) + 1.0) * out_dt
        if aux[A_NEXT_OUT] <= t:  # an interval below the stamps' resolution there
            aux[A_NEXT_OUT] = t + out_dt
        return
    while aux[A_NEXT_OUT] <= t:
        aux[A_NEXT_OUT] += out_dt


@kernel
def _interval(P: F64, aux: F64, t: float) -> float:
    """The time since the state's sample, or 0 across a logging gap (:data:`IMU_GAP_S`), whose
    uncertainty goes into the covariance and the next fix's widening instead."""
    dt: float = t - aux[A_TIME]
    if dt > IMU_GAP_S:
        dt = 0.0
        aux[A_INFLATE] = 1.0
        for i in range(3):
            P[E_VEL + i, E_VEL + i] += GAP_VEL_VAR
        P[E_ATT, E_ATT] += GAP_TILT_VAR
        P[E_ATT + 1, E_ATT + 1] += GAP_TILT_VAR
        P[E_ATT + 2, E_ATT + 2] += GAP_YAW_VAR
    return dt


@kernel
def _bridge(x: F64, P: F64, aux: F64, t: float, wheel_t: F64, wheel_v: F64) -> None:
    """Across an IMU gap the wheels still measured how far the vehicle went: move the position
    that distance (times the wheel scale the filter estimated) along the last horizontal
    velocity's direction (and the DR track with it), set the speed to the wheels' at the gap's
    end, and add to the position variance what a road turning anywhere in the gap could put it
    off, half the distance each way. On a log without wheel speed the last velocity carries it
    instead, and the variance adds the speed's own uncertainty over the gap
    (:data:`GAP_VEL_VAR`): held, the position would stay behind by the whole gap's travel while
    claiming the sigma it had before it. Where the log's wheels fall silent with the IMU (the
    recording paused), and for a vehicle standing still, the position is held; the next fix
    re-places it."""
    speed = math.hypot(x[X_VEL], x[X_VEL + 1])
    if speed < 0.1:
        return
    t0 = aux[A_TIME]
    dist, v_end = wheel_distance(t0, t, wheel_t, wheel_v)
    var = 0.0
    if dist < 0.0:
        if wheel_t.shape[0] > 0:
            return
        dist, v_end = speed * (t - t0), speed
        var = GAP_VEL_VAR * (t - t0) ** 2
    else:
        dist *= x[X_SCALE]
        v_end *= x[X_SCALE]
    ue, un = x[X_VEL] / speed, x[X_VEL + 1] / speed
    x[X_POS] += ue * dist
    x[X_POS + 1] += un * dist
    aux[A_DR] += ue * dist
    aux[A_DR + 1] += un * dist
    aux[A_DIST] += dist
    x[X_VEL] = ue * v_end
    x[X_VEL + 1] = un * v_end
    var += (0.5 * dist) ** 2
    P[E_POS, E_POS] += var
    P[E_POS + 1, E_POS + 1] += var


@kernel
def wheel_distance(t0: float, t: float, wheel_t: F64, wheel_v: F64) -> tuple[float, float]:
    """(distance, speed at ``t``) the wheels measured from ``t0`` to ``t``, or (-1, 0) where
    their samples do not cover it (none, or two more than 1 s apart)."""
    a = np.searchsorted(wheel_t, t0)
    b = np.searchsorted(wheel_t, t)
    if a == 0 or b >= wheel_t.shape[0] or b <= a:
        return -1.0, 0.0
    dist = 0.0
    for j in range(a - 1, b):
        if wheel_t[j + 1] - wheel_t[j] > 1.0:
            return -1.0, 0.0
        lo = max(wheel_t[j], t0)
        hi = min(wheel_t[j + 1], t)
        if hi > lo:
            dist += 0.5 * abs(wheel_v[j] + wheel_v[j + 1]) * (hi - lo)
    f = (t - wheel_t[b - 1]) / max(wheel_t[b] - wheel_t[b - 1], 1e-9)
    return dist, abs(wheel_v[b - 1] + f * (wheel_v[b] - wheel_v[b - 1]))


@kernel
def _hold_sample(aux: F64, t: float, gyro: F64, accel: F64, k: int) -> None:
    """Make sample ``k`` the state's time and the previous sample of the next interval."""
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


@kernel
def _gather_still_gyro(aux: F64, gyro: F64, k: int, still: bool) -> None:
    """Sum the gyro over the current stationary stretch (the ZUPT's bias observation)."""
    if still:
        for i in range(3):
            aux[A_GYRO_SUM + i] += gyro[k, i]
        aux[A_GYRO_N] += 1
    else:
        aux[A_GYRO_N] = 0.0
        for i in range(3):
            aux[A_GYRO_SUM + i] = 0.0


@kernel
def _wheel_speed(
    t: float, j: int, wheel_t: F64, wheel_v: F64, max_gap: float
) -> tuple[bool, float]:
    """(available, speed) at ``t`` from the wheel samples around it (``j``: the first after
    ``t``): interpolated between samples at most ``max_gap`` apart, or the last sample held
    for half that after the stream ends."""
    nw = wheel_t.shape[0]
    have = j > 0 and j < nw and wheel_t[j] - wheel_t[j - 1] <= max_gap
    ws = 0.0
    if have:
        f = (t - wheel_t[j - 1]) / (wheel_t[j] - wheel_t[j - 1])
        ws = wheel_v[j - 1] + f * (wheel_v[j] - wheel_v[j - 1])
    elif j > 0 and j == nw and t - wheel_t[j - 1] <= 0.5 * max_gap:
        have = True
        ws = wheel_v[j - 1]
    return have, ws
