"""Drive the EKF over a log and, in GNSS-degraded intervals, the route matcher.

The compiled loop (:func:`estimator.filter.ekf.run_until`) runs from one stop time to the next; the
driver steps in only at the start of each degraded interval and at each match attempt, where it
saves a checkpoint (the filter's plain arrays), builds the DR window, matches it
(:func:`estimator.matching.match.match_geometry`, then :func:`~estimator.matching.match.judge_match`: what
:func:`~estimator.matching.match.match_window` does) and, if the match is accepted, applies the E/N
pseudo-position update. A later run with other matching parameters resumes from the first
checkpoint whose outcome changes (``run(..., reuse=previous)``) instead of from the log start;
the attempts before it are only re-judged (the previous run's geometries are kept by their
inputs, and a gate threshold does not change them), and a baseline after a baseline is the
previous run.

When GNSS returns after pseudo-position updates, the first fix widens the E/N position variance
just enough to cover its own innovation (``ekf._widen_position``) before it is tested: the route
observations are correlated with each other and with the DR drift, so the filter's position
covariance after them is optimistic, and without the widening the chi-square gate would reject
the returning fixes for seconds and then let one through as a late, large jump. Attitude,
velocity and biases keep their covariances, so the returning fix corrects them through the
cross-covariances exactly as in normal fusion.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import uniform_filter1d

from estimator.errors import LogError, RoutefuseError
from estimator.filter import ekf
from estimator.log import Log
from estimator.matching.kernels import max_turn_deg, search_right, track_window
from estimator.matching.match import (
    MatchGeometry,
    geometry_params,
    judge_match,
    learn_lane_offset,
    match_geometry,
    route_arc_length,
)
from estimator.nav.earth import earth_rate_n, normal_gravity
from estimator.nav.frames import LocalFrame
from estimator.nav.rotation import dcm_from_euler
from estimator.params import Method, Params, for_method
from estimator.results import Epochs, MatchRecord, Run
from estimator.route import Route

F64 = NDArray[np.float64]
ProgressFn = Callable[[float], None]

_MG = 9.80665e-3
_DEG_H = math.pi / 180 / 3600
_CHUNK_S = 30.0
"""log seconds per kernel call when progress is reported"""


@dataclass(frozen=True)
class _Inputs:
    """What the kernel reads: sensor arrays on the IMU clock, in the body frame and the local
    ENU frame, plus the initial state. Depends on the log, the outages and the filter
    parameters only."""

    imu_t: F64
    gyro: F64
    accel: F64
    still: NDArray[np.bool_]
    wheel_t: F64
    wheel_v: F64
    gnss_t: F64
    gnss_pos: F64
    gnss_var: F64
    cfg: F64
    x0: F64
    P0: F64
    aux0: F64
    idx0: NDArray[np.int64]
    degraded: tuple[tuple[float, float], ...]
    warnings: tuple[str, ...]


@dataclass(frozen=True)
class _Checkpoint:
    """The filter at a stop, before anything the driver does there."""

    kind: str
    """'outage' (start of a degraded interval) or 'attempt' (a match attempt)"""
    interval: int
    k: int
    """attempt counter inside the interval: t = a + min_outage_s + k * interval_s"""
    x: F64
    P: F64
    aux: F64
    idx: NDArray[np.int64]
    n_records: int
    dist_a: float
    dist_last: float


@dataclass(frozen=True)
class _Resume:
    log: tuple
    """fingerprint of the log (:func:`_log_key`); a Run stays picklable"""
    route: Route | None
    frame: LocalFrame
    outages: tuple[tuple[float, float], ...]
    filter_key: tuple
    inputs: _Inputs
    out: F64
    n_out: int
    checkpoints: tuple[_Checkpoint, ...]
    records: tuple[MatchRecord, ...]
    memo: dict = field(default_factory=dict)
    """match geometries and long-window turns by their inputs (:meth:`_Driver._memo`), for a
    re-run to re-judge its shared attempts instead of fitting them again"""
    dropped_fixes: tuple[float, ...] = ()


# ---------------------------------------------------------------------------------------------
# public entry point


def run(
    log: Log,
    route: Route | None,
    params: Params,
    *,
    method: Method = "proposed",
    frame: LocalFrame | None = None,
    outages: Sequence[tuple[float, float]] = (),
    progress: ProgressFn | None = None,
    reuse: Run | None = None,
) -> Run:
    """Run one method over a log.

    ``outages``: (start, end) seconds after the log start where GNSS is removed. ``frame``: the
    session's local frame (default: at the log's first valid fix). ``progress``: called with the
    fraction done. ``reuse``: a previous run on the same log, route and outages; if only matching
    parameters differ, the filter resumes from the first match attempt whose outcome changes.
    """
    p = for_method(params, method)
    matching = method != "baseline"
    if matching and route is None:
        raise RoutefuseError(None, f"method {method!r} needs a route")
    outages_t = tuple((float(a), float(b)) for a, b in outages)
    for a, b in outages_t:
        if not (math.isfinite(a) and math.isfinite(b)) or b <= a:
            raise RoutefuseError(None, f"outage {a:g}:{b:g}: END must be after START")
    if frame is None:
        frame = _frame_of(log)
    old = reuse.resume if reuse is not None and isinstance(reuse.resume, _Resume) else None
    key = _filter_key(p)
    if old is not None and not (
        old.log == _log_key(log)
        and old.frame == frame
        and old.outages == outages_t
        and old.filter_key == key
        and (
            route is None
            or old.route is route
            or (old.route is not None and np.array_equal(old.route.xy, route.xy))
        )
    ):
        old = None
    inputs = old.inputs if old is not None else _prepare(log, p, frame, outages_t)
    driver = _Driver(log, route, p, matching, inputs, progress)
    if old is not None:
        driver.known_memo = old.memo
        driver.resume(
            old,
            reuse.params if reuse is not None else p,
            reuse_matching=(reuse is not None and reuse.method != "baseline"),
        )
    else:
        driver.start()
    # a baseline after a baseline is the previous run: share its (immutable) epochs, so what
    # was computed from them can be recognised (metrics.deviation_series)
    epochs = reuse.epochs if driver.copied_whole_run and reuse is not None else driver.epochs()
    if progress is not None:
        progress(1.0)
    resume = _Resume(
        log=_log_key(log),
        route=route,
        frame=frame,
        outages=outages_t,
        filter_key=key,
        inputs=inputs,
        out=driver.out,
        n_out=int(driver.idx[ekf.I_OUT]),
        checkpoints=tuple(driver.checkpoints),
        records=tuple(driver.records),
        memo=driver.memo,
        dropped_fixes=tuple(driver.dropped_fixes),
    )
    return Run(
        method=method,
        params=p,
        frame=frame,
        epochs=epochs,
        matches=tuple(driver.records),
        degraded_intervals=inputs.degraded,
        t0=log.t_start,
        dropped_fix_times=tuple(driver.dropped_fixes),
        warnings=tuple(log.warnings)
        + inputs.warnings
        + (route.warnings if route is not None else ()),
        resume=resume,
    )


def _log_key(log: Log) -> tuple:
    """Identifies a log's content cheaply: sizes, spans and sums over a sample of values."""
    imu, g = log.imu, log.gnss
    step = max(1, len(imu.t) // 4096)
    wheel = () if log.wheel is None else (len(log.wheel.t), float(np.nansum(log.wheel.speed)))
    return (
        log.path,
        len(imu.t),
        float(imu.t[0]) if len(imu.t) else 0.0,
        float(imu.t[-1]) if len(imu.t) else 0.0,
        float(np.nansum(imu.gyro[::step])),
        float(np.nansum(imu.accel[::step])),
        len(g.t),
        float(np.nansum(g.lat)),
        float(np.nansum(g.lon)),
        wheel,
    )


def _filter_key(p: Params) -> tuple:
    """Everything the filter itself (not the matcher) depends on."""
    ext = p.extensions
    return (
        p.noise,
        p.sensors,
        ext.wheel_scale_state,
        ext.robust_gnss,
        ext.portal_rerun,
        p.output_rate_hz,
    )


def _frame_of(log: Log) -> LocalFrame:
    ok = log.gnss.valid
    if not ok.any():
        raise LogError(log.path, "no valid GNSS fix: the filter cannot be initialised")
    return LocalFrame.at(log.gnss.lat[ok], log.gnss.lon[ok], log.gnss.alt[ok])


# ---------------------------------------------------------------------------------------------
# preparation: sensor arrays, stationarity, alignment


def _prepare(
    log: Log, p: Params, frame: LocalFrame, outages: tuple[tuple[float, float], ...]
) -> _Inputs:
    src = log.path
    warnings: list[str] = []
    s = p.sensors
    imu_t = np.asarray(log.imu.t, np.float64)
    gyro = np.asarray(log.imu.gyro, np.float64).reshape(-1, 3)
    accel = np.asarray(log.imu.accel, np.float64).reshape(-1, 3)
    if not (len(imu_t) == len(gyro) == len(accel)):
        raise LogError(src, "IMU time, gyro and accel arrays differ in length")
    ok = np.isfinite(imu_t) & np.all(np.isfinite(gyro), 1) & np.all(np.isfinite(accel), 1)
    if (~ok).any():
        warnings.append(f"dropped {int((~ok).sum())} non-finite IMU samples")
        imu_t, gyro, accel = imu_t[ok], gyro[ok], accel[ok]
    if len(imu_t) and np.any(np.diff(imu_t) <= 0):
        order = np.argsort(imu_t, kind="stable")
        imu_t, gyro, accel = imu_t[order], gyro[order], accel[order]
        keep = np.r_[True, np.diff(imu_t) > 0]
        warnings.append(f"IMU time not increasing: sorted, dropped {int((~keep).sum())} repeats")
        imu_t, gyro, accel = imu_t[keep], gyro[keep], accel[keep]
    if len(imu_t) < 10:
        raise LogError(src, f"only {len(imu_t)} usable IMU samples; the filter needs a stream")
    big = np.diff(imu_t) > 1.0
    if big.any():
        warnings.append(
            f"{int(big.sum())} IMU gaps longer than 1 s (largest "
            f"{float(np.max(np.diff(imu_t))):.1f} s)"
        )
    r_bi = dcm_from_euler(
        math.radians(s.imu_roll_deg), math.radians(s.imu_pitch_deg), math.radians(s.imu_yaw_deg)
    ).reshape(3, 3)
    if not np.allclose(r_bi, np.eye(3)):
        gyro = gyro @ r_bi.T
        accel = accel @ r_bi.T
    gyro = np.ascontiguousarray(gyro)
    accel = np.ascontiguousarray(accel)

    # wheel speed
    wheel_t = np.empty(0)
    wheel_v = np.empty(0)
    if log.wheel is not None and len(log.wheel.t):
        wt = np.asarray(log.wheel.t, np.float64) + s.wheel_time_offset_s
        wv = np.asarray(log.wheel.speed, np.float64)
        good = np.isfinite(wt) & np.isfinite(wv)
        order = np.argsort(wt[good], kind="stable")
        wheel_t, wheel_v = wt[good][order], wv[good][order]
    if len(wheel_t) < 2:
        warnings.append("no wheel speed: IMU + GNSS with non-holonomic constraints")
        wheel_t, wheel_v = np.empty(0), np.empty(0)

    # GNSS: valid, not in an injected outage, in the local frame, floored variances
    g = log.gnss
    valid = np.asarray(g.valid, bool).copy()
    rel = np.asarray(g.t, np.float64) - log.t_start
    for a, b in outages:
        valid &= ~((rel >= a) & (rel <= b))
    gt = np.asarray(g.t, np.float64)[valid] + s.gnss_time_offset_s
    enu = frame.to_enu(g.lat[valid], g.lon[valid], g.alt[valid])
    cov = np.asarray(g.cov_enu, np.float64).reshape(-1, 3)[valid]
    n = p.noise
    h_def, h_floor = n.gnss_sigma_default_m**2, n.gnss_sigma_floor_m**2
    var = np.empty_like(cov)
    for i, (d, f) in enumerate(((h_def, h_floor), (h_def, h_floor), (4 * h_def, 4 * h_floor))):
        c = cov[:, i]
        var[:, i] = np.maximum(np.where(np.isfinite(c) & (c > 0), c, d), f)
    good = np.all(np.isfinite(enu), 1) & np.isfinite(gt)
    order = np.argsort(gt[good], kind="stable")
    gnss_t = gt[good][order]
    gnss_pos = np.ascontiguousarray(enu[good][order])
    gnss_var = np.ascontiguousarray(var[good][order])
    if len(gnss_t) == 0:
        raise LogError(src, "no valid GNSS fix outside the outages: the filter cannot start")

    still = _stationary(imu_t, gyro, accel, wheel_t, wheel_v, p)
    cfg = _config(p, frame, wheel_t)
    # the wander follows the log's typical fix; each fix keeps the rest as white noise
    wander = n.gnss_wander_fraction * np.median(gnss_var, axis=0)
    wander[:2] = wander[:2].mean()
    gnss_var = np.ascontiguousarray(np.maximum(gnss_var - wander, [h_floor, h_floor, 4 * h_floor]))
    cfg[ekf.C_TAU_W] = n.gnss_wander_tau_s
    cfg[ekf.C_WHITE_VAR] = float(np.median(gnss_var[:, :2]))
    cfg[ekf.C_QW_H] = 2 * wander[0] / n.gnss_wander_tau_s
    cfg[ekf.C_QW_V] = 2 * wander[2] / n.gnss_wander_tau_s
    x0, P0, k0, t_fix = _align(
        src, imu_t, gyro, accel, still, wheel_t, wheel_v, gnss_t, gnss_pos, gnss_var, p, cfg
    )
    # the aligning fix measures position + wander: their errors start anti-correlated
    for i in range(3):
        a, b = ekf.E_POS + i, ekf.E_GW + i
        P0[a, a] += wander[i]
        P0[b, b] = wander[i]
        P0[a, b] = P0[b, a] = -wander[i]
    aux0 = np.zeros(ekf.NA)
    t_init = float(imu_t[k0])
    aux0[ekf.A_TIME] = t_init
    aux0[ekf.A_LAST_AID] = t_init
    aux0[ekf.A_NEXT_OUT] = t_init
    aux0[ekf.A_REJECT_SINCE] = -1.0
    aux0[ekf.A_DR : ekf.A_DR + 2] = x0[:2]
    aux0[ekf.A_TRUST_T] = t_fix
    aux0[ekf.A_PREV_GYRO : ekf.A_PREV_GYRO + 3] = gyro[k0]
    aux0[ekf.A_PREV_ACCEL : ekf.A_PREV_ACCEL + 3] = accel[k0]
    idx0 = np.zeros(ekf.NI, np.int64)
    idx0[ekf.I_IMU] = k0 + 1
    idx0[ekf.I_WHEEL] = np.searchsorted(wheel_t, t_init, side="right")
    idx0[ekf.I_GNSS] = np.searchsorted(gnss_t, t_fix, side="right")
    degraded = _degraded_intervals(gnss_t, t_fix, float(imu_t[-1]), s.gnss_gap_s)
    return _Inputs(
        imu_t=imu_t,
        gyro=gyro,
        accel=accel,
        still=still,
        wheel_t=wheel_t,
        wheel_v=wheel_v,
        gnss_t=gnss_t,
        gnss_pos=gnss_pos,
        gnss_var=gnss_var,
        cfg=cfg,
        x0=x0,
        P0=P0,
        aux0=aux0,
        idx0=idx0,
        degraded=degraded,
        warnings=tuple(warnings),
    )


def _config(p: Params, frame: LocalFrame, wheel_t: F64) -> F64:
    n = p.noise
    cfg = np.zeros(ekf.NC)
    cfg[ekf.C_COV_DT] = n.propagation_interval_s
    cfg[ekf.C_ARW2] = (math.radians(n.gyro_arw_deg_sqrt_h) / 60) ** 2
    cfg[ekf.C_VRW2] = (n.accel_vrw_m_s_sqrt_h / 60) ** 2
    cfg[ekf.C_TAU_G] = n.gyro_bias_tau_s
    cfg[ekf.C_QBG] = 2 * (n.gyro_bias_sigma_deg_h * _DEG_H) ** 2 / n.gyro_bias_tau_s
    cfg[ekf.C_TAU_A] = n.accel_bias_tau_s
    cfg[ekf.C_QBA] = 2 * (n.accel_bias_sigma_mg * _MG) ** 2 / n.accel_bias_tau_s
    cfg[ekf.C_WHEEL_VAR] = n.wheel_speed_sigma_m_s**2
    cfg[ekf.C_NHC_VAR] = n.nhc_sigma_m_s**2
    cfg[ekf.C_ZUPT_VAR] = n.zupt_sigma_m_s**2
    cfg[ekf.C_GNSS_GATE] = n.gnss_chi2_gate
    cfg[ekf.C_LEVER : ekf.C_LEVER + 3] = p.sensors.gnss_lever_arm_m
    cfg[ekf.C_GRAVITY] = normal_gravity(frame.lat0, frame.h0)
    cfg[ekf.C_WIE : ekf.C_WIE + 3] = earth_rate_n(frame.lat0)
    cfg[ekf.C_OUT_DT] = 1.0 / p.output_rate_hz
    cfg[ekf.C_AID_DT] = 1.0 / n.aid_rate_hz
    cfg[ekf.C_SCALE_ON] = float(p.extensions.wheel_scale_state and len(wheel_t) > 0)
    cfg[ekf.C_RESET_S] = n.gnss_reset_after_s
    cfg[ekf.C_ROBUST] = float(p.extensions.robust_gnss)
    gap = float(np.median(np.diff(wheel_t))) if len(wheel_t) > 1 else 0.0
    cfg[ekf.C_WHEEL_GAP] = max(0.5, 5 * gap)
    return cfg


def _stationary(
    imu_t: F64, gyro: F64, accel: F64, wheel_t: F64, wheel_v: F64, p: Params
) -> NDArray[np.bool_]:
    """Per IMU sample: the vehicle is stopped. With wheel speed: the wheels say so and the
    gyro, averaged over 0.5 s, is quiet; without: the gyro is quiet and |accel| barely varies."""
    n = p.noise
    dt = float(np.median(np.diff(imu_t)))
    m = max(3, round(0.5 / max(dt, 1e-4)))
    g_mean = uniform_filter1d(gyro, m, axis=0, mode="nearest")
    quiet = np.linalg.norm(g_mean, axis=1) < math.radians(n.zupt_gyro_deg_s)
    with np.errstate(over="ignore", invalid="ignore"):
        a = np.linalg.norm(accel, axis=1)
        a_var = (
            uniform_filter1d(a * a, m, mode="nearest") - uniform_filter1d(a, m, mode="nearest") ** 2
        )
        imu_still = quiet & (np.sqrt(np.maximum(a_var, 0)) < n.zupt_accel_std_m_s2)
    if len(wheel_t) < 2:
        return imu_still
    j = np.clip(np.searchsorted(wheel_t, imu_t), 1, len(wheel_t) - 1)
    gap = wheel_t[j] - wheel_t[j - 1]
    covered = (imu_t >= wheel_t[0] - 0.5) & (imu_t <= wheel_t[-1] + 0.5) & (gap <= 1.0)
    ws = np.interp(imu_t, wheel_t, np.abs(wheel_v))
    return np.where(covered, (ws < n.zupt_speed_m_s) & quiet, imu_still)


def _align(
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
) -> tuple[F64, F64, int, float]:
    """Initial state and covariance at the IMU sample of the aligning fix.

    Heading: configured, or the chord between the first two fixes ``align_distance_m`` apart
    (at the chord's mid-time), carried to the second fix with the gyro. Roll and pitch: the
    accelerometer averaged over the last second, less the motion's own acceleration (from the
    wheel or GNSS speed and the yaw rate). Covariances say how good each of these is.
    """
    s = p.sensors
    n = p.noise
    first_imu = imu_t[0]
    use = np.flatnonzero(gnss_t >= first_imu)
    if len(use) == 0:
        raise LogError(src, "every GNSS fix is before the first IMU sample")
    yaw_rate = gyro[:, 2]
    cum_yaw = np.r_[0.0, np.cumsum(0.5 * (yaw_rate[1:] + yaw_rate[:-1]) * np.diff(imu_t))]

    def yaw_between(t0: float, t1: float) -> float:
        return float(np.interp(t1, imu_t, cum_yaw) - np.interp(t0, imu_t, cum_yaw))

    if s.initial_heading_deg is not None:
        j = int(use[0])
        yaw = math.radians(s.initial_heading_deg)
        sig_yaw = math.radians(2.0)
        speed = None
    else:
        d_min = s.align_distance_m
        max_span = max(20.0, d_min / 0.5)
        j = -1
        for i in use:
            hi = np.searchsorted(gnss_t, gnss_t[i] + max_span, side="right")
            d = np.hypot(*(gnss_pos[i + 1 : hi, :2] - gnss_pos[i, :2]).T)
            far = np.flatnonzero(d >= d_min)
            if len(far) == 0:
                continue
            jj = int(i + 1 + far[0])
            turn = yaw_between(gnss_t[i], gnss_t[jj])
            if abs(turn) > math.radians(30):
                continue
            chord = gnss_pos[jj, :2] - gnss_pos[i, :2]
            t_mid = 0.5 * (gnss_t[i] + gnss_t[jj])
            yaw = math.atan2(chord[1], chord[0]) + yaw_between(t_mid, gnss_t[jj])
            if len(wheel_t) > 1:
                w_sel = (wheel_t >= gnss_t[i]) & (wheel_t <= gnss_t[jj])
                if w_sel.any() and np.mean(wheel_v[w_sel]) < 0:
                    yaw += math.pi
            sig_h = math.sqrt(gnss_var[i, 0] + gnss_var[jj, 0])
            sig_yaw = math.sqrt(
                (sig_h / float(np.hypot(*chord))) ** 2 + (0.2 * turn) ** 2 + math.radians(1.0) ** 2
            )
            speed = float(np.hypot(*chord)) / (gnss_t[jj] - gnss_t[i])
            j = jj
            break
        if j < 0:
            raise LogError(
                src,
                f"cannot align: the GNSS track never moves {d_min:g} m in a "
                "fairly straight line; set sensors.initial_heading_deg",
            )
    t_fix = float(gnss_t[j])
    k0 = int(np.searchsorted(imu_t, t_fix, side="right") - 1)
    k0 = max(k0, 0)
    t0 = float(imu_t[k0])

    # speed and along-track acceleration at t0
    if len(wheel_t) > 1 and wheel_t[0] <= t0 + 0.5 and wheel_t[-1] >= t0 - 0.5:
        speed = float(np.interp(t0, wheel_t, wheel_v))
        sel = (wheel_t >= t0 - 1.0) & (wheel_t <= t0)
        if sel.sum() >= 2 and np.ptp(wheel_t[sel]) > 0.2:
            acc_x = float(np.polyfit(wheel_t[sel] - t0, wheel_v[sel], 1)[0])
        else:
            acc_x = 0.0
    else:
        if speed is None:
            speed = 0.0
        acc_x = 0.0
    if still[k0] and abs(speed) < 1.0:
        # without wheel speed the IMU-only stillness test also fires on a smooth cruise; a GNSS
        # chord that moved says otherwise
        speed = 0.0
    # roll, pitch from the accelerometer over the last second
    sel = (imu_t >= t0 - 1.0) & (imu_t <= t0)
    f = accel[sel].mean(axis=0) if sel.any() else accel[k0]
    w_z = float(gyro[sel, 2].mean()) if sel.any() else 0.0
    up = f - np.array([acc_x, speed * w_z, 0.0])
    up /= max(float(np.linalg.norm(up)), 1e-9)
    roll = math.atan2(up[1], up[2])
    pitch = math.atan2(up[0], math.hypot(up[1], up[2]))
    sig_tilt = math.radians(0.3 if still[sel].all() else 1.5)
    q = ekf.euler_to_quat(roll, pitch, yaw)
    C = np.empty((3, 3))
    ekf.quat_to_dcm(q, C)
    v = np.array([math.cos(yaw), math.sin(yaw), 0.0]) * speed
    lever = C @ np.asarray(s.gnss_lever_arm_m, np.float64)
    x0 = np.zeros(ekf.NX)
    x0[ekf.X_POS : ekf.X_POS + 3] = gnss_pos[j] - lever - v * (t_fix - t0)
    x0[ekf.X_VEL : ekf.X_VEL + 3] = v
    x0[ekf.X_QUAT : ekf.X_QUAT + 4] = q
    x0[ekf.X_SCALE] = 1.0
    sig_v = n.velocity_init_sigma_m_s
    diag = np.zeros(ekf.NE)
    diag[0:3] = [sig_tilt**2, sig_tilt**2, sig_yaw**2]
    diag[3:6] = sig_v**2
    diag[6:9] = gnss_var[j]
    diag[9:12] = (n.gyro_bias_init_sigma_deg_h * _DEG_H) ** 2
    diag[12:15] = (n.accel_bias_init_sigma_mg * _MG) ** 2
    diag[15] = n.wheel_scale_sigma**2 if cfg[ekf.C_SCALE_ON] > 0 else 0.0
    return x0, np.diag(diag), k0, t_fix


def _degraded_intervals(
    gnss_t: F64, t_start: float, t_end: float, gap_s: float
) -> tuple[tuple[float, float], ...]:
    """Stretches after ``t_start`` with no valid fix for longer than ``gap_s``: (last fix,
    next fix), or (last fix, log end)."""
    ft = gnss_t[(gnss_t >= t_start) & (gnss_t <= t_end)]
    edges = np.r_[ft, t_end]
    d = np.diff(edges)
    return tuple((float(edges[i]), float(edges[i + 1])) for i in np.flatnonzero(d > gap_s))


# ---------------------------------------------------------------------------------------------
# the driver


@dataclass
class _Track:
    """Where on the route the vehicle is, and the lane offset of the current interval."""

    lane: float = 0.0
    s: float | None = None
    s_dist: float = 0.0


@dataclass
class _Driver:
    log: Log
    route: Route | None
    p: Params
    matching: bool
    inp: _Inputs
    progress: ProgressFn | None
    x: F64 = field(init=False)
    P: F64 = field(init=False)
    aux: F64 = field(init=False)
    idx: NDArray[np.int64] = field(init=False)
    out: F64 = field(init=False)
    checkpoints: list[_Checkpoint] = field(default_factory=list)
    records: list[MatchRecord] = field(default_factory=list)
    track: _Track = field(default_factory=_Track)
    dropped_fixes: list[float] = field(default_factory=list)
    """times of the fixes the fixed-lag re-runs left out"""
    memo: dict[tuple, Any] = field(default_factory=dict)
    """this run's match geometries and long-window turns, by their inputs"""
    known_memo: dict[tuple, Any] = field(default_factory=dict)
    """the previous run's, when this one reuses it"""
    copied_whole_run: bool = False
    """the run is the reused one (a baseline after a baseline)"""

    # --- state handling
    def _set_state(self, x: F64, P: F64, aux: F64, idx: NDArray[np.int64]) -> None:
        self.x, self.P, self.aux, self.idx = x.copy(), P.copy(), aux.copy(), idx.copy()

    def _checkpoint(
        self, kind: str, interval: int, k: int, dist_a: float, dist_last: float
    ) -> None:
        self.checkpoints.append(
            _Checkpoint(
                kind=kind,
                interval=interval,
                k=k,
                x=self.x.copy(),
                P=self.P.copy(),
                aux=self.aux.copy(),
                idx=self.idx.copy(),
                n_records=len(self.records),
                dist_a=dist_a,
                dist_last=dist_last,
            )
        )

    def _alloc(self) -> None:
        inp = self.inp
        span = float(inp.imu_t[-1] - inp.imu_t[inp.idx0[ekf.I_IMU] - 1])
        n = int(span * self.p.output_rate_hz) + 16
        if self.matching:
            tr = self.p.trigger
            n += sum(int((b - a) / tr.interval_s) + 2 for a, b in inp.degraded)
        self.out = np.zeros((n, ekf.NO))

    def _grow(self) -> None:
        self.out = np.vstack([self.out, np.zeros((len(self.out) // 2 + 16, ekf.NO))])

    def _advance(self, t_stop: float, gnss: tuple[F64, F64, F64] | None = None) -> None:
        """Run the filter to ``t_stop``; ``gnss`` (times, positions, variances) replaces the
        log's fixes (the fixed-lag re-run)."""
        inp = self.inp
        gnss_t, gnss_pos, gnss_var = (
            (inp.gnss_t, inp.gnss_pos, inp.gnss_var) if gnss is None else gnss
        )
        t_end = float(inp.imu_t[-1])
        t_first = float(inp.imu_t[inp.idx0[ekf.I_IMU] - 1])
        while True:
            t_now = self.aux[ekf.A_TIME]
            target = t_stop
            if self.progress is not None:
                # from the next IMU sample: a gap longer than a chunk must not stall the loop
                k = int(self.idx[ekf.I_IMU])
                t_next = float(inp.imu_t[k]) if k < len(inp.imu_t) else t_now
                target = min(t_stop, max(t_now, t_next) + _CHUNK_S)
            status = ekf.run_until(
                target,
                self.x,
                self.P,
                self.aux,
                self.idx,
                inp.imu_t,
                inp.gyro,
                inp.accel,
                inp.still,
                inp.wheel_t,
                inp.wheel_v,
                gnss_t,
                gnss_pos,
                gnss_var,
                inp.cfg,
                self.out,
            )
            if status == ekf.STATUS_FULL:
                self._grow()
                continue
            if status == ekf.STATUS_DIVERGED:
                raise LogError(
                    self.log.path,
                    "the filter diverged (non-finite state) at "
                    f"t = {self.aux[ekf.A_TIME] - self.log.t_start:.2f} s",
                )
            if self.progress is not None:
                span = max(t_end - t_first, 1e-9)
                self.progress(min(1.0, (self.aux[ekf.A_TIME] - t_first) / span))
            if target >= t_stop or self.idx[ekf.I_IMU] >= len(inp.imu_t):
                return

    def _advance_to_outage(self, t_a: float) -> None:
        """Run to the start of a degraded interval (``t_a``, the last fix before the gap).

        With ``extensions.portal_rerun``: at a tunnel portal fixes jump by metres while still
        claiming metre-level sigmas, and a filter that accepted some of them enters the tunnel
        from a corrupted position it then carries through the whole outage. So the state
        ``noise.gnss_rerun_lag_s`` before the gap is saved, the fixes since then are tested
        against where the filter would have dead-reckoned without them
        (:func:`_disagreeing_fixes`), and if any disagrees the last seconds are processed again
        from the saved state without those fixes."""
        lag = self.p.noise.gnss_rerun_lag_s
        if not (self.p.extensions.portal_rerun and lag > 0):
            self._advance(t_a)
            return
        self._advance(t_a - lag)
        saved = (self.x.copy(), self.P.copy(), self.aux.copy(), self.idx.copy())
        self._advance(t_a)
        inp = self.inp
        g0, g1 = int(saved[3][ekf.I_GNSS]), int(self.idx[ekf.I_GNSS])
        if g1 <= g0:
            return
        drop = _disagreeing_fixes(saved, t_a, inp, range(g0, g1))
        if not drop:
            return
        keep = np.ones(len(inp.gnss_t), bool)
        keep[drop] = False
        self._set_state(*saved)
        self._advance(t_a, (inp.gnss_t[keep], inp.gnss_pos[keep], inp.gnss_var[keep]))
        # every fix up to t_a is behind the filter, in the log's own indexing as well
        self.idx[ekf.I_GNSS] = g1
        self.dropped_fixes.extend(float(inp.gnss_t[g]) for g in drop)

    def _write_row(self) -> int:
        if self.idx[ekf.I_OUT] >= len(self.out) - 1:
            self._grow()
        ekf.write_row(self.x, self.P, self.aux, self.idx, self.out)
        return int(self.idx[ekf.I_OUT]) - 1

    # --- the route part
    def _begin_interval(self, t_a: float, out: F64, n_out: int, x: F64, aux: F64) -> None:
        rows = out[:n_out]
        tr = self.track
        pred = None if tr.s is None else tr.s + (aux[ekf.A_DIST] - tr.s_dist)
        tr.s = route_arc_length(self.route, x[:2], s_guess=pred, params=self.p)
        tr.s_dist = float(aux[ekf.A_DIST])
        used = rows[:, ekf.O_GNSS] > 0
        # the offset is learned around the last epoch a fix was used in, which may lie well
        # before t_a (fixes rejected or left out at the portal): a search window centred on
        # the vehicle would clip the older epochs onto its end, with metres of false offset
        last = np.flatnonzero(used & (rows[:, ekf.O_T] <= t_a))
        s_last = tr.s
        if len(last):
            s_last = tr.s - (float(aux[ekf.A_DIST]) - float(rows[last[-1], ekf.O_DIST]))
        tr.lane = learn_lane_offset(
            rows[:, ekf.O_T],
            rows[:, ekf.O_POS : ekf.O_POS + 2],
            used,
            self.route,
            t_end=t_a,
            params=self.p,
            s_guess=s_last,
        )

    def _window(self, out: F64, n_out: int, x: F64, aux: F64, length_m: float) -> F64:
        """The DR track over the last ``length_m`` of travel, integrated from the mechanised
        velocity only (no correction jumps), translated to end at the estimate."""
        dist = out[:n_out, ekf.O_DIST]
        d_now = float(aux[ekf.A_DIST])
        i0 = max(search_right(dist, d_now - length_m) - 1, 0)
        return track_window(
            out[:n_out, ekf.O_DR : ekf.O_DR + 2],
            dist,
            aux[ekf.A_DR : ekf.A_DR + 2],
            d_now,
            i0,
            x[:2] - aux[ekf.A_DR : ekf.A_DR + 2],
        )

    def _match(self, out: F64, n_out: int, x: F64, P: F64, aux: F64) -> MatchRecord:
        """One attempt's match (P must be propagated to the attempt time).

        A bend much gentler than the window (an expressway's 12 deg over 500 m) has no shape
        inside a 250 m window: sliding along an arc is a rotation, which the rigid fit absorbs,
        so along-track stays unobserved however long the tunnel. Seen whole in a longer window
        the bend is a corner, whose place along the road the fit finds. The longer window only
        replaces an accepted standard match that left along-track unobserved, only where the
        road is gentle (no standard-length stretch of it turns more than
        ``window.long_max_turn_deg``: sharper bends the standard window observes itself, and over
        a long window they make the fit depend on how well the map's arc length matches the
        lane's), and only if it passes every gate itself (``extensions.long_window``)."""
        tr = self.track
        pred = None if tr.s is None else tr.s + (aux[ekf.A_DIST] - tr.s_dist)
        w = self.p.window

        def attempt(window_xy: F64, params: Params) -> MatchRecord:
            geometry = self._geometry(window_xy, x[:2].copy(), P[6:8, 6:8].copy(), pred, params)
            return judge_match(
                geometry, params, index=len(self.records), t=float(aux[ekf.A_TIME]), epoch=n_out
            )

        rec = attempt(self._window(out, n_out, x, aux, w.length_m), self.p)
        if not (
            self.p.extensions.long_window
            and w.long_length_m > w.length_m
            and rec.accepted
            and not rec.extra.get("along_observed", 1.0)
        ):
            return rec
        long_xy = self._window(out, n_out, x, aux, w.long_length_m)
        turn = self._memo(
            ("turn", w.length_m, w.spacing_m),
            (long_xy,),
            lambda: _max_turn_deg(long_xy, w.length_m, w.spacing_m),
        )
        if turn > w.long_max_turn_deg:
            return rec
        # map and DR shape errors are correlated over tens of metres: the long window's points
        # count as many as the standard window's, not as independent extra information
        po = self.p.pseudo
        noise = po.shape_noise_m * math.sqrt(w.long_length_m / w.length_m)
        long = attempt(
            long_xy,
            dataclasses.replace(self.p, pseudo=dataclasses.replace(po, shape_noise_m=noise)),
        )
        if not (long.accepted and long.extra.get("along_observed", 0.0)):
            return rec
        extra = {
            **long.extra,
            "long_window": 1.0,
            "long_window_turn_deg": turn,
            "short_window_length_m": rec.extra.get("window_length_m", w.length_m),
        }
        return dataclasses.replace(long, extra=extra)

    def _memo(self, key: tuple, arrays: tuple[F64, ...], compute: Callable[[], Any]) -> Any:
        """``compute()``, or the value this run or the previous one computed for the same key
        and array contents."""
        digest = hashlib.blake2b(digest_size=16)
        for a in arrays:
            a = np.ascontiguousarray(a, np.float64)
            digest.update(repr(a.shape).encode())
            digest.update(a.tobytes())
        full = (*key, digest.digest())
        value = self.known_memo.get(full, self.memo.get(full))
        if value is None:
            value = compute()
        self.memo[full] = value
        return value

    def _geometry(
        self, window_xy: F64, p_dr: F64, cov: F64, pred: float | None, params: Params
    ) -> MatchGeometry:
        """:func:`match_geometry` of an attempt, or the previous run's for the same inputs
        (window, position, covariance, route guess, lane offset and the parameters the geometry
        depends on): after a gate change the attempts before the first changed outcome are only
        re-judged, not fitted again."""
        lane = self.track.lane
        return self._memo(
            ("geometry", pred, lane, geometry_params(params)),
            (window_xy, p_dr, cov),
            lambda: match_geometry(
                window_xy, p_dr, cov, self.route, s_guess=pred, lane_offset=lane, params=params
            ),
        )

    def _after_match(self, rec: MatchRecord, x_after: F64, aux: F64) -> None:
        if rec.accepted:
            tr = self.track
            pred = None if tr.s is None else tr.s + (aux[ekf.A_DIST] - tr.s_dist)
            tr.s = route_arc_length(self.route, x_after[:2], s_guess=pred, params=self.p)
            tr.s_dist = float(aux[ekf.A_DIST])

    def _attempt_live(self) -> None:
        ekf.flush_covariance(self.P, self.aux, self.inp.cfg)
        n_out = int(self.idx[ekf.I_OUT])
        rec = self._match(self.out, n_out, self.x, self.P, self.aux)
        innovation, correction = rec.innovation, np.zeros(2)
        if rec.accepted:
            res = ekf.pseudo_position_update(
                self.x,
                self.P,
                self.aux,
                self.inp.cfg,
                np.asarray(rec.pseudo_position, float),
                _applied_obs_cov(rec, self.p),
                np.array([rec.extra["normal_e"], rec.extra["normal_n"]])
                * float(self.p.extensions.lane_offset_state),
            )
            innovation, correction = res[:2].copy(), res[2:].copy()
            heading = _heading_observation(rec, self.p)
            if heading is not None:
                applied = ekf.heading_update(
                    self.x, self.P, self.aux, self.inp.cfg, heading[0], heading[1] ** 2
                )
                extra = {
                    **rec.extra,
                    "heading_obs_rad": heading[0],
                    "heading_obs_sigma_rad": heading[1],
                    "heading_correction_rad": applied,
                }
                rec = dataclasses.replace(rec, extra=extra)
            if not ekf._finite(self.x, self.P):
                raise LogError(
                    self.log.path,
                    "the filter diverged (non-finite state) after "
                    f"the route update at t = {rec.t - self.log.t_start:.2f} s",
                )
        epoch = self._write_row()
        rec = dataclasses.replace(rec, epoch=epoch, innovation=innovation, correction=correction)
        self.records.append(rec)
        self._after_match(rec, self.x, self.aux)

    # --- the loop
    def start(self) -> None:
        inp = self.inp
        self._set_state(inp.x0, inp.P0, inp.aux0, inp.idx0)
        self._alloc()
        self._write_row()
        self.aux[ekf.A_NEXT_OUT] = self.aux[ekf.A_TIME] + inp.cfg[ekf.C_OUT_DT]
        self._loop(0, None)

    def _loop(self, i0: int, at: _Checkpoint | None) -> None:
        """Run live from the start of interval ``i0``, or from the attempt checkpoint ``at``
        (whose attempt is redone)."""
        tr = self.p.trigger
        spacing = self.p.window.spacing_m
        for i in range(i0, len(self.inp.degraded)):
            a, b = self.inp.degraded[i]
            if at is not None and i == at.interval:
                k, dist_a, dist_last = at.k, at.dist_a, at.dist_last
            else:
                self._advance_to_outage(a)
                dist_a = float(self.aux[ekf.A_DIST])
                dist_last = -math.inf
                k = 0
                self._checkpoint("outage", i, 0, dist_a, dist_last)
                if not self.matching:
                    continue
                self._begin_interval(a, self.out, int(self.idx[ekf.I_OUT]), self.x, self.aux)
                if self.p.extensions.lane_offset_state and self.track.s is not None:
                    t = self.route.tangent_at(self.track.s)[0]
                    ekf.clone_lane_offset(self.P, self.aux, self.inp.cfg, np.array([-t[1], t[0]]))
            while True:
                t_try = a + tr.min_outage_s + k * tr.interval_s
                if t_try >= b or t_try > self.inp.imu_t[-1]:
                    break
                if at is None or i != at.interval or k != at.k:
                    self._advance(t_try)
                d = float(self.aux[ekf.A_DIST])
                if d - dist_a >= tr.min_outage_distance_m and d - dist_last >= spacing:
                    if at is None or i != at.interval or k != at.k:
                        self._checkpoint("attempt", i, k, dist_a, dist_last)
                    self._attempt_live()
                    dist_last = d
                k += 1
            at = None
        self._advance(math.inf)

    def resume(self, old: _Resume, old_params: Params, *, reuse_matching: bool) -> None:
        """Replay the old run's checkpoints with the new matching parameters until one gives a
        different outcome, then run live from there."""
        self.out = old.out
        outage_cps = [c for c in old.checkpoints if c.kind == "outage"]
        same_trigger = (
            self.p.trigger == old_params.trigger
            and self.p.extensions.heading_observation == old_params.extensions.heading_observation
            and self.p.extensions.lane_offset_state == old_params.extensions.lane_offset_state
        )
        if not self.matching and not reuse_matching:
            # baseline after baseline: the filter and its inputs are the same, so is the run
            self._copy_old(old, len(old.checkpoints), old.n_out)
            self.records = []
            self.copied_whole_run = True
            return
        if not self.matching or not reuse_matching or not same_trigger:
            if not outage_cps:
                self._copy_old(old, len(old.checkpoints), old.n_out)
                self.records = []
                return
            first = outage_cps[0]
            self._restart(old, first, old.checkpoints.index(first), [])
            self._loop(first.interval, None)
            return
        records: list[MatchRecord] = []
        for n_cp, cp in enumerate(old.checkpoints):
            n_out = int(cp.idx[ekf.I_OUT])
            if cp.kind == "outage":
                a = self.inp.degraded[cp.interval][0]
                self._begin_interval(a, old.out, n_out, cp.x, cp.aux)
                continue
            P = cp.P.copy()
            aux = cp.aux.copy()
            ekf.flush_covariance(P, aux, self.inp.cfg)
            self.records = records
            rec = self._match(old.out, n_out, cp.x, P, aux)
            prev = old.records[cp.n_records]
            if not _same_outcome(rec, prev):
                self._restart(old, cp, n_cp + 1, records)
                self._loop(cp.interval, cp)
                return
            applied = {k: v for k, v in prev.extra.items() if k.startswith("heading_")}
            rec = dataclasses.replace(
                rec,
                epoch=prev.epoch,
                innovation=prev.innovation,
                correction=prev.correction,
                extra={**rec.extra, **applied},
            )
            records.append(rec)
            x_after = old.out[prev.epoch, ekf.O_POS : ekf.O_POS + 3]
            self._after_match(rec, x_after, aux)
        self._copy_old(old, len(old.checkpoints), old.n_out)
        self.records = records

    def _copy_old(self, old: _Resume, n_checkpoints: int, n_out: int) -> None:
        self.dropped_fixes = list(old.dropped_fixes)
        self.out = old.out
        self.checkpoints = list(old.checkpoints[:n_checkpoints])
        self.idx = np.zeros(ekf.NI, np.int64)
        self.idx[ekf.I_OUT] = n_out

    def _restart(
        self, old: _Resume, cp: _Checkpoint, n_keep: int, records: list[MatchRecord]
    ) -> None:
        self.checkpoints = list(old.checkpoints[:n_keep])
        self.records = list(records)
        self.dropped_fixes = [t for t in old.dropped_fixes if t <= cp.aux[ekf.A_TIME]]
        self._set_state(cp.x, cp.P, cp.aux, cp.idx)
        self.out = old.out.copy()

    def epochs(self) -> Epochs:
        n = int(self.idx[ekf.I_OUT])
        o = self.out[:n]
        t = o[:, ekf.O_T].copy()
        starts = np.array([a for a, _ in self.inp.degraded])
        ends = np.array([b for _, b in self.inp.degraded])
        if len(starts):
            j = np.searchsorted(starts, t, side="right") - 1
            degraded = (j >= 0) & (t <= ends[np.clip(j, 0, None)])
        else:
            degraded = np.zeros(n, bool)
        return Epochs(
            t=t,
            position=np.ascontiguousarray(o[:, ekf.O_POS : ekf.O_POS + 3]),
            velocity=np.ascontiguousarray(o[:, ekf.O_VEL : ekf.O_VEL + 3]),
            attitude=np.ascontiguousarray(o[:, ekf.O_RPY : ekf.O_RPY + 3]),
            position_sigma=np.ascontiguousarray(o[:, ekf.O_SIG_POS : ekf.O_SIG_POS + 3]),
            yaw_sigma=o[:, ekf.O_SIG_YAW].copy(),
            gnss_used=o[:, ekf.O_GNSS] > 0,
            degraded=degraded,
        )


def _disagreeing_fixes(
    saved: tuple[F64, F64, F64, NDArray[np.int64]],
    t_stop: float,
    inp: _Inputs,
    fixes: range,
) -> list[int]:
    """The fixes (indices into ``inp.gnss_*``) that disagree with the filter dead-reckoned
    from the ``saved`` state (x, P, aux, idx) to ``t_stop`` without GNSS.

    Each fix's offset from the dead-reckoned antenna position (plus the GNSS wander state) is
    tested twice, with the chi-square (2 dof) gate ``noise.gnss_chi2_gate``. Against the
    filter: the saved E/N covariance of position + wander, the growth of the position variance
    while dead-reckoning, and the log's *typical* white fix variance (not the one the fix
    reports: portal fixes claim metre-level sigmas for jumps of 5-15 m). Against the other
    fixes: over a few seconds dead reckoning drifts by centimetres, so good fixes share one
    offset (the filter's error) up to their white noise and the wander's change, and a jump
    the wheels did not drive stands out from the largest set of fixes that agree with each
    other, if that set holds more than half of them. The second test still works when the
    saved state is loose (a portal shortly after another outage)."""
    x, P, aux, idx = (a.copy() for a in saved)
    cfg = inp.cfg
    t_save = float(aux[ekf.A_TIME])
    n_rows = int((t_stop - t_save) / cfg[ekf.C_OUT_DT]) + 64
    rows = np.zeros((n_rows, ekf.NO))
    idx[ekf.I_OUT] = 0
    ekf.write_row(x, P, aux, idx, rows)
    aux[ekf.A_NEXT_OUT] = t_save + cfg[ekf.C_OUT_DT]
    no_t, no_xyz = np.empty(0), np.empty((0, 3))
    status = ekf.run_until(
        t_stop, x, P, aux, idx, inp.imu_t, inp.gyro, inp.accel, inp.still, inp.wheel_t,
        inp.wheel_v, no_t, no_xyz, no_xyz, cfg, rows,
    )  # fmt: skip
    if status != ekf.STATUS_DONE or len(fixes) == 0:
        return []
    ekf.write_row(x, P, aux, idx, rows)
    r = rows[: int(idx[ekf.I_OUT])]
    t_r = r[:, ekf.O_T]
    g = np.asarray(fixes)
    tf = inp.gnss_t[g]
    pos = np.column_stack([np.interp(tf, t_r, r[:, ekf.O_POS + i]) for i in range(2)])
    rpy = np.column_stack([np.interp(tf, t_r, np.unwrap(r[:, ekf.O_RPY + i])) for i in range(3)])
    lever = cfg[ekf.C_LEVER : ekf.C_LEVER + 3]
    C = np.empty((3, 3))
    lever_en = np.empty((len(g), 2))
    for k in range(len(g)):
        ekf.quat_to_dcm(ekf.euler_to_quat(rpy[k, 0], rpy[k, 1], rpy[k, 2]), C)
        lever_en[k] = (C @ lever)[:2]
    gw0 = saved[0][ekf.X_GW : ekf.X_GW + 2]
    gw = gw0[None, :] * np.exp(-(tf - t_save) / cfg[ekf.C_TAU_W])[:, None]
    d = inp.gnss_pos[g, :2] - (pos + lever_en + gw)
    sig2 = np.column_stack([np.interp(tf, t_r, r[:, ekf.O_SIG_POS + i] ** 2) for i in range(2)])
    growth = np.maximum(sig2 - r[0, ekf.O_SIG_POS : ekf.O_SIG_POS + 2] ** 2, 0.0)
    white = cfg[ekf.C_WHITE_VAR]
    gate = cfg[ekf.C_GNSS_GATE]
    pe, pw = slice(ekf.E_POS, ekf.E_POS + 2), slice(ekf.E_GW, ekf.E_GW + 2)
    P0 = saved[1]
    S0 = P0[pe, pe] + P0[pw, pw] + P0[pe, pw] + P0[pw, pe]
    bad = np.zeros(len(g), bool)
    for k in range(len(g)):
        S = S0 + np.diag(growth[k] + white)
        bad[k] = float(d[k] @ np.linalg.solve(S, d[k])) > gate
    # the fixes among themselves: two white noises, the wander's change over the lag, and
    # what a heading or odometer-scale error turns the distance driven into
    driven = float(r[-1, ekf.O_DIST] - r[0, ekf.O_DIST])
    drift2 = (P0[ekf.E_ATT + 2, ekf.E_ATT + 2] + P0[ekf.E_SCALE, ekf.E_SCALE]) * driven**2
    var_pair = 2.0 * white + cfg[ekf.C_QW_H] * (t_stop - t_save) + drift2
    d2 = np.sum((d[:, None, :] - d[None, :, :]) ** 2, axis=2) / var_pair
    support = d2 <= gate
    best = int(np.argmax(support.sum(axis=1)))
    agree = support[best]
    if 2 * int(agree.sum()) > len(g):
        centre = d[agree].mean(axis=0)
        bad |= np.sum((d - centre) ** 2, axis=1) / var_pair > gate
    return [int(i) for i in g[bad]]


def _max_turn_deg(xy: F64, stretch_m: float, spacing_m: float) -> float:
    """The largest heading change over any ``stretch_m`` of a polyline, in degrees (the
    polyline resampled every ``spacing_m`` from its end; compiled:
    :func:`estimator.matching.kernels.max_turn_deg`)."""
    pts = np.ascontiguousarray(np.asarray(xy, np.float64)[:, :2])
    return float(max_turn_deg(pts, float(stretch_m), float(spacing_m)))


UNOBSERVED_VAR = 1e8
"""m^2: the along-track variance a match that does not observe along-track is applied with."""


def _applied_obs_cov(rec: MatchRecord, p: Params) -> F64:
    """The covariance an accepted match updates the filter with.

    Where route shape leaves along-track unobserved, the record says so with
    ``pseudo.along_sigma_max_m`` (100 m). Applied as it is, once a second, that would still be
    information: 350 such updates in a straight tunnel claim along-track to 100 / sqrt(350) = 5 m
    when nothing was observed, which without wheel speed (along-track drifting by hundreds of
    metres) makes the filter confident of a position it never measured and then reject the
    bends that do observe it. So the along-track axis is applied as unobserved (cross-track
    only). Only with ``extensions.geometry_covariance``; the paper's isotropic R is kept."""
    cov = np.asarray(rec.obs_cov, float)
    if not (p.extensions.geometry_covariance and rec.extra.get("along_observed", 1.0) == 0.0):
        return cov
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    w[-1] = max(w[-1], UNOBSERVED_VAR)
    return (v * w) @ v.T


def _heading_observation(rec: MatchRecord, p: Params) -> tuple[float, float] | None:
    """(yaw innovation, 1-sigma) from an accepted match's fitted rotation, or None.

    The rotation that maps the DR window onto the route is the heading error the window was
    dead-reckoned with. Its sigma is that of a rigid fit of ``n_pairs`` points spread over the
    window's length with the registration residual as point noise (sqrt(12 / N) / L), floored
    at 0.1 deg; the window's own heading drift is part of the residual."""
    if not (p.extensions.heading_observation and rec.accepted and rec.n_pairs >= 3):
        return None
    dyaw = float(rec.rotation_rad)
    length = (rec.n_pairs - 1) * p.window.spacing_m
    if not (math.isfinite(dyaw) and length > 0):
        return None
    noise = max(float(rec.residual_m), 0.5) if math.isfinite(rec.residual_m) else 0.5
    sigma = max(noise * math.sqrt(12.0 / rec.n_pairs) / length, math.radians(0.1))
    return dyaw, sigma


def _same_outcome(new: MatchRecord, old: MatchRecord) -> bool:
    """Whether a re-evaluated attempt leaves the filter exactly as the old one did."""
    if new.accepted != old.accepted:
        return False
    if not new.accepted:
        return True
    return bool(
        np.array_equal(new.pseudo_position, old.pseudo_position)
        and np.array_equal(new.obs_cov, old.obs_cov)
        and new.rotation_rad == old.rotation_rad
        and new.n_pairs == old.n_pairs
        and new.residual_m == old.residual_m
    )
