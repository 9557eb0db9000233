"""Initial alignment: the state and covariance at the IMU sample of the aligning fix.

Heading: configured, or the chord between the first two fixes ``sensors.align_distance_m``
apart (at the chord's mid-time), carried to the second fix with the gyro. Roll and pitch: the
accelerometer averaged over the last second, less the motion's own acceleration (from the
wheel speed, else from the GNSS track; and the yaw rate). Covariances say how good each of these
is."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from estimator.errors import LogError
from estimator.filter.layout import C_SCALE_ON, E_GSF, NE, NX, X_POS, X_QUAT, X_SCALE, X_VEL
from estimator.filter.quaternion import euler_to_quat, quat_to_dcm
from estimator.params import Params

F64 = NDArray[np.float64]

MG = 9.80665e-3
"""m/s^2 per milli-g"""
DEG_H = math.pi / 180 / 3600
"""rad/s per deg/h"""
ACCEL_PRIOR_SIGMA_M_S2 = 1.0
"""a car's forward acceleration, 1 sigma, where nothing measures it: the prior the GNSS track's
own estimate is weighed against when an alignment in motion has no wheel speed"""
ACCEL_MIN_FIXES = 6
"""fixes a parabola needs for the track's acceleration and the scatter that says how sure it is"""
ACCEL_AHEAD_SPAN_S = 5.0
"""how far from the aligning chord's start ``extensions.align_track_accel_ahead`` may reach for
fixes: a car's acceleration holds for seconds, not for a whole drive's start"""


def align(
    src: str,
    imu_t: F64,
    gyro: F64,
    accel: F64,
    still: NDArray[np.bool_],
    wheel_t: F64,
    wheel_v: F64,
    gnss_t: F64,
    gnss_pos: F64,
    gnss_var: F64,
    p: Params,
    cfg: F64,
) -> tuple[F64, F64, int, float, tuple[str, ...]]:
    """(x0, P0, IMU index k0, time of the aligning fix, warnings about the fixes left out of the
    alignment). ``src`` names the log in errors."""
    s = p.sensors
    use = np.flatnonzero(gnss_t >= imu_t[0])
    if len(use) == 0:
        raise LogError(src, "every GNSS fix is before the first IMU sample")
    yaw_rate = gyro[:, 2]
    cum_yaw = np.r_[0.0, np.cumsum(0.5 * (yaw_rate[1:] + yaw_rate[:-1]) * np.diff(imu_t))]

    def yaw_between(t0: float, t1: float) -> float:
        return float(np.interp(t1, imu_t, cum_yaw) - np.interp(t0, imu_t, cum_yaw))

    speed: float | None
    notes: tuple[str, ...] = ()
    if s.initial_heading_deg is not None:
        i = j = int(use[0])
        yaw = math.radians(s.initial_heading_deg)
        sig_yaw = math.radians(2.0)
        speed = None
    else:
        found = _chord_heading(use, gnss_t, gnss_pos, gnss_var, wheel_t, wheel_v, p, yaw_between)
        if found is None:
            raise LogError(
                src,
                f"cannot align: the GNSS track never moves {s.align_distance_m:g} m in a "
                "fairly straight line; set sensors.initial_heading_deg",
            )
        i, j, yaw, sig_yaw, speed = found
        notes = _left_out(use, j, gnss_t, gnss_pos, yaw, speed)
    t_fix = float(gnss_t[j])
    k0 = int(np.searchsorted(imu_t, t_fix, side="right") - 1)
    k0 = max(k0, 0)
    t0 = float(imu_t[k0])
    acc = acc_var = 0.0
    unlevelled: F64 | None = None
    if speed is not None and p.extensions.align_track_accel and not _wheels_cover(t0, wheel_t):
        end = j + 1
        if p.extensions.align_track_accel_ahead and end - i < ACCEL_MIN_FIXES:
            reach = int(np.searchsorted(gnss_t, gnss_t[i] + ACCEL_AHEAD_SPAN_S, side="right"))
            end = max(end, min(i + ACCEL_MIN_FIXES, reach))
        chord_t = gnss_t[i:end]
        headings = yaw - (np.interp(t_fix, imu_t, cum_yaw) - np.interp(chord_t, imu_t, cum_yaw))
        told = _track_accel(chord_t, gnss_pos[i:end, :2], headings)
        if told is None:
            unlevelled = chord_t
        else:
            acc, acc_var = told
            speed += acc * 0.5 * float(gnss_t[j] - gnss_t[i])  # the chord's mean is at its middle
    speed, acc_x = _speed_at(t0, wheel_t, wheel_v, speed, acc)
    if still[k0] and abs(speed) < 1.0:
        # without wheel speed the IMU-only stillness test also fires on a smooth cruise; a GNSS
        # chord that moved says otherwise
        speed = 0.0
        acc_x = acc_var = 0.0
        unlevelled = None
    roll, pitch, sig_tilt = _tilt(imu_t, gyro, accel, still, t0, k0, speed, acc_x, acc_var)
    if unlevelled is not None:
        notes += (_unlevelled_note(unlevelled, t_fix - float(gnss_t[use[0]]), sig_tilt),)
    q = euler_to_quat(roll, pitch, yaw)
    C = np.empty((3, 3))
    quat_to_dcm(q, C)
    v = np.array([math.cos(yaw), math.sin(yaw), 0.0]) * speed
    lever = C @ np.asarray(s.gnss_lever_arm_m, np.float64)
    x0 = np.zeros(NX)
    x0[X_POS : X_POS + 3] = gnss_pos[j] - lever - v * (t_fix - t0)
    x0[X_VEL : X_VEL + 3] = v
    x0[X_QUAT : X_QUAT + 4] = q
    x0[X_SCALE] = 1.0
    n = p.noise
    sig_v = n.velocity_init_sigma_m_s
    diag = np.zeros(NE)
    diag[0:3] = [sig_tilt**2, sig_tilt**2, sig_yaw**2]
    diag[3:6] = sig_v**2
    diag[6:9] = gnss_var[j]
    diag[9:12] = (n.gyro_bias_init_sigma_deg_h * DEG_H) ** 2
    diag[12:15] = (n.accel_bias_init_sigma_mg * MG) ** 2
    diag[15] = n.wheel_scale_sigma**2 if cfg[C_SCALE_ON] > 0 else 0.0
    if p.extensions.gyro_scale_consider or p.extensions.gyro_scale_state:
        diag[E_GSF] = (n.gyro_scale_sigma_ppm * 1e-6) ** 2
    return x0, np.diag(diag), k0, t_fix, notes


def _left_out(
    use: NDArray[np.intp], j: int, gnss_t: F64, gnss_pos: F64, yaw: float, speed: float
) -> tuple[str, ...]:
    """The fixes before the aligning one whose chord the alignment refused, each with how far
    it lies from the track the aligning chord runs back along (heading and speed at it)."""
    first = int(use[0])
    chord_start = int(np.searchsorted(gnss_t, gnss_t[j] - 60.0))
    direction = np.array([math.cos(yaw), math.sin(yaw)])
    out = []
    for i in range(first, j):
        back = gnss_pos[j, :2] - direction * speed * (gnss_t[j] - gnss_t[i])
        off = float(np.hypot(*(gnss_pos[i, :2] - back)))
        if i >= chord_start and off > 5.0:
            out.append(
                f"GNSS fix at {gnss_t[i] - gnss_t[first]:.1f} s after the first left out of "
                f"the initial alignment: {off:.0f} m off the track of the fixes after it"
            )
    return tuple(out[:5])


def _chord_heading(
    use: NDArray[np.intp],
    gnss_t: F64,
    gnss_pos: F64,
    gnss_var: F64,
    wheel_t: F64,
    wheel_v: F64,
    p: Params,
    yaw_between: Callable[[float, float], float],
) -> tuple[int, int, float, float, float] | None:
    """(chord's first fix, its last (the aligning fix), yaw, yaw sigma, mean speed) from the
    first fairly straight chord of ``align_distance_m``, or None."""
    d_min = p.sensors.align_distance_m
    max_span = max(20.0, d_min / 0.5)
    for i in use:
        hi = np.searchsorted(gnss_t, gnss_t[i] + max_span, side="right")
        d = np.hypot(*(gnss_pos[i + 1 : hi, :2] - gnss_pos[i, :2]).T)
        far = np.flatnonzero(d >= d_min)
        if len(far) == 0:
            continue
        jj = max(int(i + 1 + far[0]), int(i) + 2)  # a fix between the ends to check them
        if jj >= hi:
            continue
        turn = yaw_between(gnss_t[i], gnss_t[jj])
        if abs(turn) > math.radians(30):
            continue
        chord = gnss_pos[jj, :2] - gnss_pos[i, :2]
        sig_h = math.sqrt(gnss_var[i, 0] + gnss_var[jj, 0])
        if not _chord_consistent(gnss_pos[i : jj + 1, :2], sig_h, turn):
            continue
        travelled = _travelled(wheel_t, wheel_v, float(gnss_t[i]), float(gnss_t[jj]))
        length = float(np.hypot(*chord))
        if travelled is not None and abs(length - travelled) > 3 * sig_h + 0.1 * travelled + 1:
            continue
        t_mid = 0.5 * (gnss_t[i] + gnss_t[jj])
        yaw = math.atan2(chord[1], chord[0]) + yaw_between(t_mid, gnss_t[jj])
        if len(wheel_t) > 1:
            w_sel = (wheel_t >= gnss_t[i]) & (wheel_t <= gnss_t[jj])
            if w_sel.any() and np.mean(wheel_v[w_sel]) < 0:
                yaw += math.pi
        sig_yaw = math.sqrt(
            (sig_h / float(np.hypot(*chord))) ** 2 + (0.2 * turn) ** 2 + math.radians(1.0) ** 2
        )
        speed = float(np.hypot(*chord)) / (gnss_t[jj] - gnss_t[i])
        return int(i), jj, yaw, sig_yaw, speed
    return None


def _travelled(wheel_t: F64, wheel_v: F64, t0: float, t1: float) -> float | None:
    """Distance the wheels measured between two times (None where they do not cover both)."""
    if len(wheel_t) < 2 or wheel_t[0] > t0 or wheel_t[-1] < t1:
        return None
    grid = np.linspace(t0, t1, 50)
    return float(np.trapezoid(np.abs(np.interp(grid, wheel_t, wheel_v)), grid))


def _chord_consistent(track: F64, sigma: float, turn: float) -> bool:
    """Whether the fixes between a chord's ends lie along it: a bad fix at either end (a first
    fix 50 m off) turns the chord away from the road, and the fixes between then stand off
    it. Allowed off the chord: three sigmas of the ends' noise plus the sagitta of an arc
    turning ``turn`` over the chord (L |turn| / 8) and 2 m."""
    if len(track) < 3:
        return True
    chord = track[-1] - track[0]
    length = float(np.hypot(*chord))
    if length == 0.0:
        return False
    normal = np.array([-chord[1], chord[0]]) / length
    off = np.abs((track[1:-1] - track[0]) @ normal)
    allowed = 3.0 * sigma + length * abs(turn) / 8.0 + 2.0
    return bool(np.median(off) <= allowed)


def _wheels_cover(t0: float, wheel_t: F64) -> bool:
    return len(wheel_t) > 1 and wheel_t[0] <= t0 + 0.5 and wheel_t[-1] >= t0 - 0.5


def _track_accel(t: F64, pos: F64, headings: F64) -> tuple[float, float] | None:
    """The along-track acceleration of the GNSS fixes ``t``, ``pos`` (the aligning chord, the
    vehicle's yaw at each in ``headings``) and its variance: a parabola's through the distance
    along the track, weighed against :data:`ACCEL_PRIOR_SIGMA_M_S2`. Each step between fixes
    is taken along the yaw between them (the gyro's): projected on one direction, a chord
    turning 30 deg in a second at a steady 10 m/s would read 1.3 m/s^2. Left out,
    a car accelerating 1.4 m/s^2 as the log begins (comma2k19) is levelled 9 deg nose-up
    under a 1.5 deg sigma, and every second of dead reckoning after it runs slow. The fit's
    scatter, not the fixes' claimed variance, sets its sigma: a receiver's error is mostly
    common to fixes a second apart, and the track's shape is far better than its place.

    Where the fixes cannot tell it (fewer than six, or a parabola less sure than the prior)
    it is None, the alignment as without it (and a warning says so): a tilt widened to the
    prior's 6 deg lets the non-holonomic constraint turn an IMU mounted tilted towards the
    velocity within the first seconds (IMU-only sim 4, GNSS lost 3 s in: 117 -> 338 m)."""
    mid = 0.5 * (headings[1:] + headings[:-1])
    steps = np.diff(pos, axis=0)
    s = np.r_[0.0, np.cumsum(steps[:, 0] * np.cos(mid) + steps[:, 1] * np.sin(mid))]
    dt = t - t[-1]
    prior = ACCEL_PRIOR_SIGMA_M_S2**2
    if len(t) < ACCEL_MIN_FIXES or float(np.ptp(dt)) < 0.5:
        return None
    coef, cov = np.polyfit(dt, s, 2, cov=True)
    fit, fit_var = 2.0 * float(coef[0]), 4.0 * float(cov[0, 0])
    if not (math.isfinite(fit) and fit_var < prior):
        return None
    # a Gaussian product: prior N(0, prior), fit N(fit, fit_var)
    gain = prior / (prior + fit_var)
    return gain * fit, (1.0 - gain) * prior


def _unlevelled_note(fixes_t: F64, t_align: float, sig_tilt: float) -> str:
    """The warning for an alignment in motion levelled as if the car held its speed: no
    wheel speed, and too few fixes on and after the aligning chord (a 1 Hz receiver) or too
    much scatter for :func:`_track_accel` to tell its acceleration. An acceleration a levels roll
    or pitch a / g off (0.58 deg per 0.1 m/s^2) under the tilt sigma ``sig_tilt`` the
    alignment claims, and a tilt error is dead reckoning's fastest-growing one. ``fixes_t``:
    the fixes the parabola was given; ``t_align``: the aligning fix, s after the first."""
    return (
        f"initial alignment at {t_align:.1f} s after the first GNSS fix levelled "
        f"as if the vehicle held its speed: no wheel speed, and {len(fixes_t)} fixes over "
        f"{float(np.ptp(fixes_t)):.1f} s cannot tell its acceleration (each 0.1 m/s^2 tilts "
        f"roll or pitch 0.6 deg; the alignment claims {math.degrees(sig_tilt):.1f} deg); "
        "start the log at standstill or give it wheel speed"
    )


def _speed_at(
    t0: float, wheel_t: F64, wheel_v: F64, chord_speed: float | None, track_accel: float = 0.0
) -> tuple[float, float]:
    """Speed and along-track acceleration at ``t0``: from the wheels when they cover it, else
    the chord's speed (0 when the heading was configured) and the track's acceleration."""
    if _wheels_cover(t0, wheel_t):
        speed = float(np.interp(t0, wheel_t, wheel_v))
        sel = (wheel_t >= t0 - 1.0) & (wheel_t <= t0)
        if sel.sum() >= 2 and np.ptp(wheel_t[sel]) > 0.2:
            acc_x = float(np.polyfit(wheel_t[sel] - t0, wheel_v[sel], 1)[0])
        else:
            acc_x = 0.0
        return speed, acc_x
    return (0.0 if chord_speed is None else chord_speed), track_accel


def _tilt(
    imu_t: F64,
    gyro: F64,
    accel: F64,
    still: NDArray[np.bool_],
    t0: float,
    k0: int,
    speed: float,
    acc_x: float,
    acc_var: float = 0.0,
) -> tuple[float, float, float]:
    """Roll, pitch and their sigma from the accelerometer over the last second. ``acc_var`` is
    the variance of ``acc_x`` where the wheels did not measure it: an acceleration error a
    levels the IMU a / g off, so the tilt's sigma grows by sqrt(acc_var) / g."""
    sel = (imu_t >= t0 - 1.0) & (imu_t <= t0)
    f = accel[sel].mean(axis=0) if sel.any() else accel[k0]
    w_z = float(gyro[sel, 2].mean()) if sel.any() else 0.0
    up = f - np.array([acc_x, speed * w_z, 0.0])
    up /= max(float(np.linalg.norm(up)), 1e-9)
    roll = math.atan2(up[1], up[2])
    pitch = math.atan2(up[0], math.hypot(up[1], up[2]))
    sig_tilt = math.radians(0.3 if still[sel].all() else 1.5)
    if acc_var > 0.0:  # a dead accelerometer (all zeros) levels as before, without a division
        sig_tilt = math.hypot(sig_tilt, math.sqrt(acc_var) / max(float(np.linalg.norm(f)), 1e-9))
    return roll, pitch, sig_tilt
