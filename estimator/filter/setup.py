"""What the compiled filter reads, made from a log: sensor arrays repaired and on one clock (IMU
in the body frame, GNSS in the session's ENU frame, injected outages removed), per-sample
stationarity, the run's constants packed for the kernel, the aligned initial state, and the
GNSS-degraded intervals where the route matcher steps in."""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from estimator.errors import LogError, named_and_summed
from estimator.filter.alignment import DEG_H, MG, align
from estimator.filter.kernel import IMU_GAP_S, wheel_distance
from estimator.filter.layout import (
    A_DR,
    A_LAST_AID,
    A_NEXT_OUT,
    A_PREV_ACCEL,
    A_PREV_GYRO,
    A_REJECT_SINCE,
    A_TIME,
    A_TRUST_T,
    C_AID_DT,
    C_ARW2,
    C_COV_DT,
    C_CROSS_WIDEN,
    C_GNSS_GATE,
    C_GRAVITY,
    C_GSF_BLIND,
    C_GSF_EST,
    C_LEVER,
    C_NHC_TILT2,
    C_NHC_VAR,
    C_OUT_DT,
    C_QBA,
    C_QBG,
    C_QW_H,
    C_QW_V,
    C_RESET_S,
    C_ROBUST,
    C_SCALE_ON,
    C_TAU_A,
    C_TAU_G,
    C_TAU_W,
    C_VRW2,
    C_WHEEL_GAP,
    C_WHEEL_VAR,
    C_WHITE_VAR,
    C_WIE,
    C_ZUPT_VAR,
    E_GW,
    E_POS,
    I_GNSS,
    I_IMU,
    I_WHEEL,
    NA,
    NC,
    NI,
)
from estimator.filter.mounting import mount_warning, mount_yaw
from estimator.filter.moving_mean import moving_mean
from estimator.io.plausibility import off_the_imu_clock, topic_of
from estimator.log import Log, wheel_gap_s
from estimator.nav.earth import earth_rate_n, normal_gravity
from estimator.nav.frames import LocalFrame
from estimator.nav.rotation import dcm_from_euler
from estimator.params import Params, SensorParams, matching_params

F64 = NDArray[np.float64]
Outages = tuple[tuple[float, float], ...]


REALIGN_WITHIN_S = 30.0
"""After an IMU gap the filter is aligned afresh when the GNSS track gives a chord this soon
after the gap's end; later, the fixes' own corrections are left to bring the heading back."""
REALIGN_FIX_AT_END_S = 1.0
"""...and only when GNSS was there as the IMU came back (a fix this soon after the gap's end).
A gap that ends in a tunnel is left to the GNSS return at the portal, whose first fixes are too
noisy for a short chord (a 20 m chord through them was 15-20 deg off)."""


@dataclass(frozen=True)
class Realignment:
    """A fresh alignment after an IMU gap: the navigation state (attitude, velocity, position)
    and its covariance at the IMU sample at ``t``, which replace the state carried across the
    gap (whose heading the gap left unknown); the sensor biases are kept."""

    t: float
    x: F64
    P: F64


@dataclass(frozen=True)
class FilterInputs:
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
    realignments: tuple[Realignment, ...] = ()
    """after each IMU gap the GNSS track could align, in time order"""


def prepare_inputs(log: Log, p: Params, frame: LocalFrame, outages: Outages) -> FilterInputs:
    """The kernel's inputs for one log: ``outages`` are (start, end) seconds after the log start
    where GNSS is removed; ``p`` is already resolved for the method (:func:`for_method`)."""
    src = log.path
    warnings: list[str] = []
    s = p.sensors
    imu_t, gyro, accel = _imu_arrays(log, s, warnings)
    wheel_t, wheel_v = _wheel_arrays(log, s, warnings)
    gnss_t, gnss_pos, gnss_var = _gnss_arrays(log, p, frame, outages)
    warnings.extend(_mounting(log, s, imu_t, gyro, accel, wheel_t, wheel_v, gnss_t, gnss_pos))
    gaps = np.flatnonzero(np.diff(imu_t) > IMU_GAP_S)
    gnss_t, gnss_pos, gnss_var, left_out = _outside_imu_gaps(
        imu_t, gaps, gnss_t, gnss_pos, gnss_var
    )
    n = p.noise
    h_floor = n.gnss_sigma_floor_m**2
    still = stationary(imu_t, gyro, accel, wheel_t, wheel_v, p)
    cfg = kernel_config(p, frame, wheel_t)
    # the wander follows the log's typical fix; each fix keeps the rest as white noise
    wander = n.gnss_wander_fraction * np.median(gnss_var, axis=0)
    wander[:2] = wander[:2].mean()
    gnss_var = np.ascontiguousarray(np.maximum(gnss_var - wander, [h_floor, h_floor, 4 * h_floor]))
    cfg[C_TAU_W] = n.gnss_wander_tau_s
    cfg[C_WHITE_VAR] = float(np.median(gnss_var[:, :2]))
    cfg[C_QW_H] = 2 * wander[0] / n.gnss_wander_tau_s
    cfg[C_QW_V] = 2 * wander[2] / n.gnss_wander_tau_s
    x0, P0, k0, t_fix, notes = align(
        src, imu_t, gyro, accel, still, wheel_t, wheel_v, gnss_t, gnss_pos, gnss_var, p, cfg
    )
    warnings.extend(notes)
    after_gaps = _realignments(
        src,
        imu_t,
        gaps,
        gyro,
        accel,
        still,
        wheel_t,
        wheel_v,
        gnss_t,
        gnss_pos,
        gnss_var,
        p,
        cfg,
    )
    warnings.extend(
        imu_gap_warnings(
            imu_t[gaps] - log.t_start,
            imu_t[gaps + 1] - log.t_start,
            left_out,
            tuple(None if r is None else r.t - log.t_start for r in after_gaps),
            have_wheel=len(wheel_t) > 0,
            wheels_silent=tuple(
                wheel_distance(imu_t[g], imu_t[g + 1], wheel_t, wheel_v)[0] < 0.0 for g in gaps
            ),
        )
    )
    realignments = tuple(r for r in after_gaps if r is not None)
    # the aligning fix measures position + wander: their errors start anti-correlated
    for i in range(3):
        a, b = E_POS + i, E_GW + i
        P0[a, a] += wander[i]
        P0[b, b] = wander[i]
        P0[a, b] = P0[b, a] = -wander[i]
    aux0 = _initial_aux(x0, float(imu_t[k0]), t_fix, gyro[k0], accel[k0])
    idx0 = np.zeros(NI, np.int64)
    idx0[I_IMU] = k0 + 1
    idx0[I_WHEEL] = np.searchsorted(wheel_t, float(imu_t[k0]), side="right")
    idx0[I_GNSS] = np.searchsorted(gnss_t, t_fix, side="right")
    degraded = degraded_intervals(gnss_t, t_fix, float(imu_t[-1]), s.gnss_gap_s)
    return FilterInputs(
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
        realignments=realignments,
    )


def _realignments(
    src: str,
    imu_t: F64,
    gaps: NDArray[np.intp],
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
) -> tuple[Realignment | None, ...]:
    """An alignment after every IMU gap (``gaps``: the index of the last IMU sample before
    each) from the first :data:`REALIGN_WITHIN_S` of the data after it, the same way the run's
    start is aligned (several fixes, motion consistency). Across a gap the wheels carry the
    position, but where the road turned in it nothing measured the heading: fixes then pull
    the position back while a heading tens of degrees off drags it away again, for minutes.
    None where the track after the gap cannot align (a gap in a tunnel: the bridged state goes
    on) or where the heading is configured."""
    found: list[Realignment | None] = []
    for g in gaps:
        k1 = int(g) + 1
        b = float(imu_t[k1])
        # the fixes and samples the alignment can reach (its fixes' span and the second
        # before): a log broken into thousands of gaps costs thousands of short alignments,
        # not whole logs
        lo = int(np.searchsorted(gnss_t, b, side="left"))
        hi = int(np.searchsorted(gnss_t, b + REALIGN_WITHIN_S, side="right"))
        k2 = int(np.searchsorted(imu_t, b + REALIGN_WITHIN_S + 1.0, side="right"))
        aligned = None
        if (
            p.sensors.initial_heading_deg is None
            and hi - lo >= 2
            and gnss_t[lo] <= b + REALIGN_FIX_AT_END_S
        ):
            with contextlib.suppress(LogError):
                aligned = align(
                    src,
                    imu_t[k1:k2],
                    gyro[k1:k2],
                    accel[k1:k2],
                    still[k1:k2],
                    wheel_t,
                    wheel_v,
                    gnss_t[lo:hi],
                    gnss_pos[lo:hi],
                    gnss_var[lo:hi],
                    p,
                    cfg,
                )
        if aligned is None:
            found.append(None)
            continue
        x, P, k, _t_fix, _notes = aligned
        found.append(Realignment(t=float(imu_t[k1 + k]), x=x, P=P))
    return tuple(found)


def imu_gap_warnings(
    start: F64,
    end: F64,
    left_out: NDArray[np.intp],
    realigned: tuple[float | None, ...],
    *,
    have_wheel: bool,
    wheels_silent: tuple[bool, ...] = (),
) -> list[str]:
    """One line per IMU gap (``start``-``end``, s after the log start): how the position was
    carried across it, the fixes inside it left out, and whether the filter was aligned
    afresh after it (at ``realigned``, s) or its heading carried across is left to the fixes
    after it. Beyond :data:`~estimator.errors.WARNING_LINES_NAMED` gaps, the rest are summed up
    in one line (their span, their total length, the fixes left out, how many were
    re-aligned). ``wheels_silent``: the gaps the log's wheels fell silent in too (a paused
    recording), where the position is held (:func:`~estimator.filter.kernel._bridge`)."""
    bridge = (
        "carried along the wheel speed"
        if have_wheel
        else "carried along the last velocity (no wheel speed; its sigma widened for the speed)"
    )
    held = "held (the wheels silent in it too: a paused recording?)"
    silent = wheels_silent if have_wheel else ()
    n = len(start)
    gaps, summed = named_and_summed(range(n))
    lines = []
    for i in gaps:
        at = realigned[i]
        done = (
            f"re-aligned from the GNSS track at {at:.1f} s"
            if at is not None
            else f"not re-aligned (no straight GNSS track within {REALIGN_WITHIN_S:g} s after "
            "it): the next fixes re-place it and its heading"
        )
        lines.append(
            f"IMU gap {start[i]:.1f}-{end[i]:.1f} s: no estimate inside it, the position "
            f"{held if i < len(silent) and silent[i] else bridge}; {int(left_out[i])} fixes "
            f"inside it not used; {done}"
        )
    if summed:
        first = summed[0]
        rest = slice(first, n)
        total = float(np.sum(end[rest] - start[rest]))
        again = sum(at is not None for at in realigned[rest])
        n_held = sum(silent[first:])
        how = bridge if not n_held else f"{bridge} or, in {n_held} of them, {held}"
        lines.append(
            f"... and {n - first} more IMU gaps between {start[first]:.1f} and {end[-1]:.1f} s "
            f"({total:.1f} s in all, the position {how}; {int(np.sum(left_out[rest]))} fixes "
            f"inside them not used; {again} re-aligned from the GNSS track, "
            f"{n - first - again} not)"
        )
    return lines


def _outside_imu_gaps(
    imu_t: F64, gaps: NDArray[np.intp], gnss_t: F64, gnss_pos: F64, gnss_var: F64
) -> tuple[F64, F64, F64, NDArray[np.intp]]:
    """The fixes outside the IMU's logging gaps (``gaps``: the index of the last IMU sample
    before each, longer than :data:`IMU_GAP_S`), and how many each gap held. Inside one there
    is no state to test a fix against: taken at the gap's end, minutes-old fixes moved by the
    old velocity would each pull the state somewhere else. The filter carries the state across
    the gap (along the wheels' distance where they cover it) and re-places it at the first fix
    after it."""
    lo = np.searchsorted(gnss_t, imu_t[gaps], side="right")
    hi = np.searchsorted(gnss_t, imu_t[gaps + 1], side="left")
    inside = np.maximum(hi - lo, 0)
    if not inside.any():
        return gnss_t, gnss_pos, gnss_var, inside
    keep = np.ones(len(gnss_t), bool)
    for a, b in zip(lo, hi, strict=True):
        keep[a:b] = False
    return gnss_t[keep], gnss_pos[keep], gnss_var[keep], inside


def _imu_arrays(log: Log, s: SensorParams, warnings: list[str]) -> tuple[F64, F64, F64]:
    """IMU time, gyro and accel: non-finite samples dropped, time sorted without repeats, and
    rotated from the IMU's mounting into the body frame."""
    src = log.path
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
    return imu_t, np.ascontiguousarray(gyro), np.ascontiguousarray(accel)


def _mounting(
    log: Log,
    s: SensorParams,
    imu_t: F64,
    gyro: F64,
    accel: F64,
    wheel_t: F64,
    wheel_v: F64,
    gnss_t: F64,
    gnss_pos: F64,
) -> tuple[str, ...]:
    """A line when the IMU, turned by the configured mounting, is still not forward-left-up
    (:func:`estimator.filter.mounting.mount_warning`). Judged here, where the configuration is
    known, not when the log is read: there a Husky's IMU on its side and turned -90 deg would
    be named whatever its configuration says."""
    found = mount_yaw(imu_t, gyro, accel, wheel_t, wheel_v, gnss_t, gnss_pos[:, :2])
    name = Path(log.path).name
    line = mount_warning(
        name, topic_of(log, "imu"), found, s.imu_roll_deg, s.imu_pitch_deg, s.imu_yaw_deg
    )
    return () if line is None else (line,)


def _wheel_arrays(log: Log, s: SensorParams, warnings: list[str]) -> tuple[F64, F64]:
    """Wheel speed on the IMU clock, finite and sorted; empty when there are fewer than two, or
    when none falls in the IMU's span (a stream on another clock: the run is then one without
    wheels, with those parameters, not one that waits for wheel samples that never come)."""
    wheel_t = np.empty(0)
    wheel_v = np.empty(0)
    logged_t = np.empty(0)
    if log.wheel is not None and len(log.wheel.t):
        logged_t = np.asarray(log.wheel.t, np.float64)
        wt = logged_t + s.wheel_time_offset_s
        wv = np.asarray(log.wheel.speed, np.float64)
        good = np.isfinite(wt) & np.isfinite(wv)
        order = np.argsort(wt[good], kind="stable")
        wheel_t, wheel_v = wt[good][order], wv[good][order]
    imu_t = log.imu.t
    if len(wheel_t) and (wheel_t[0] > imu_t[-1] or wheel_t[-1] < imu_t[0]):
        # named by the loader (plausibility) when that far off as logged
        if not off_the_imu_clock(imu_t, logged_t).all():
            warnings.append(
                f"wheel speed stamped {wheel_t[0] - log.t_start:.1f}-"
                f"{wheel_t[-1] - log.t_start:.1f} s (with sensors.wheel_time_offset_s = "
                f"{s.wheel_time_offset_s:g}) does not overlap the IMU's 0.0-"
                f"{log.t_end - log.t_start:.1f} s: IMU and GNSS only"
            )
        return np.empty(0), np.empty(0)
    if len(wheel_t) < 2:
        warnings.append("no wheel speed: IMU + GNSS with non-holonomic constraints")
        wheel_t, wheel_v = np.empty(0), np.empty(0)
    return wheel_t, wheel_v


def fix_wander_var(cfg: F64) -> F64:
    """(3,) E, N, U m^2: the stationary variance of the GNSS wander state that
    :func:`prepare_inputs` took out of each fix's variance (``FilterInputs.gnss_var`` plus
    this is a fix's whole variance, or more where the white rest was raised to the floor)."""
    tau = float(cfg[C_TAU_W])
    var: F64 = np.array([cfg[C_QW_H], cfg[C_QW_H], cfg[C_QW_V]]) * tau / 2.0
    return var


def _gnss_arrays(log: Log, p: Params, frame: LocalFrame, outages: Outages) -> tuple[F64, F64, F64]:
    """GNSS fixes: valid, not in an injected outage, in the local frame, sorted, with floored
    variances (a default where the receiver reports none)."""
    s = p.sensors
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
        raise LogError(log.path, "no valid GNSS fix outside the outages: the filter cannot start")
    return gnss_t, gnss_pos, gnss_var


def _initial_aux(x0: F64, t_init: float, t_fix: float, gyro0: F64, accel0: F64) -> F64:
    aux0 = np.zeros(NA)
    aux0[A_TIME] = t_init
    aux0[A_LAST_AID] = t_init
    aux0[A_NEXT_OUT] = t_init
    aux0[A_REJECT_SINCE] = -1.0
    aux0[A_DR : A_DR + 2] = x0[:2]
    aux0[A_TRUST_T] = t_fix
    aux0[A_PREV_GYRO : A_PREV_GYRO + 3] = gyro0
    aux0[A_PREV_ACCEL : A_PREV_ACCEL + 3] = accel0
    return aux0


def route_errors_estimated(p: Params) -> bool:
    """Whether an outage's route pseudo-positions estimate the map-bias and lane-offset errors
    of an applied bias rather than only consider them: a matching parameter, which the outage's
    start writes into ``aux[A_ROUTE_EST]`` (:func:`~estimator.filter.updates.clone_route_errors`)
    with the rest of what it clones, not the run's constants."""
    return p.extensions.map_bias and p.offset.map_bias_estimated


def kernel_config(p: Params, frame: LocalFrame, wheel_t: F64) -> F64:
    """The run's constants as the kernel reads them (``cfg``; the GNSS wander's are added by
    :func:`prepare_inputs`, which knows the log's typical fix)."""
    n = p.noise
    cfg = np.zeros(NC)
    cfg[C_COV_DT] = n.propagation_interval_s
    cfg[C_ARW2] = (math.radians(n.gyro_arw_deg_sqrt_h) / 60) ** 2
    cfg[C_VRW2] = (n.accel_vrw_m_s_sqrt_h / 60) ** 2
    cfg[C_TAU_G] = n.gyro_bias_tau_s
    cfg[C_QBG] = 2 * (n.gyro_bias_sigma_deg_h * DEG_H) ** 2 / n.gyro_bias_tau_s
    cfg[C_TAU_A] = n.accel_bias_tau_s
    cfg[C_QBA] = 2 * (n.accel_bias_sigma_mg * MG) ** 2 / n.accel_bias_tau_s
    cfg[C_WHEEL_VAR] = n.wheel_speed_sigma_m_s**2
    cfg[C_NHC_VAR] = n.nhc_sigma_m_s**2
    cfg[C_NHC_TILT2] = math.radians(n.nhc_mount_sigma_deg) ** 2
    cfg[C_ZUPT_VAR] = n.zupt_sigma_m_s**2
    cfg[C_GNSS_GATE] = n.gnss_chi2_gate
    cfg[C_LEVER : C_LEVER + 3] = p.sensors.gnss_lever_arm_m
    cfg[C_GRAVITY] = normal_gravity(frame.lat0, frame.h0)
    cfg[C_WIE : C_WIE + 3] = earth_rate_n(frame.lat0)
    cfg[C_OUT_DT] = 1.0 / p.output_rate_hz
    cfg[C_AID_DT] = 1.0 / n.aid_rate_hz
    cfg[C_SCALE_ON] = float(p.extensions.wheel_scale_state and len(wheel_t) > 0)
    cfg[C_RESET_S] = n.gnss_reset_after_s
    cfg[C_ROBUST] = float(p.extensions.robust_gnss)
    cautious = matching_params(p, have_wheel=len(wheel_t) > 0)
    cfg[C_CROSS_WIDEN] = float(cautious.extensions.cross_track_heading_widen)
    cfg[C_GSF_EST] = float(p.extensions.gyro_scale_state)
    cfg[C_GSF_BLIND] = float(
        p.extensions.gyro_scale_consider
        and p.extensions.gyro_scale_blind_gain
        and not p.extensions.gyro_scale_state
    )
    cfg[C_WHEEL_GAP] = wheel_gap_s(wheel_t)
    return cfg


def stationary(
    imu_t: F64, gyro: F64, accel: F64, wheel_t: F64, wheel_v: F64, p: Params
) -> NDArray[np.bool_]:
    """Per IMU sample: the vehicle is stopped. With wheel speed: the wheels say so and the
    gyro, averaged over 0.5 s, is quiet; without: the gyro is quiet and |accel| barely varies."""
    n = p.noise
    dt = float(np.median(np.diff(imu_t)))
    m = max(3, round(0.5 / max(dt, 1e-4)))
    g_mean = moving_mean(gyro, m)
    quiet = np.linalg.norm(g_mean, axis=1) < math.radians(n.zupt_gyro_deg_s)
    with np.errstate(over="ignore", invalid="ignore"):
        a = np.linalg.norm(accel, axis=1)
        a_var = moving_mean(a * a, m) - moving_mean(a, m) ** 2
        imu_still: NDArray[np.bool_] = quiet & (
            np.sqrt(np.maximum(a_var, 0)) < n.zupt_accel_std_m_s2
        )
    if len(wheel_t) < 2:
        return imu_still
    j = np.clip(np.searchsorted(wheel_t, imu_t), 1, len(wheel_t) - 1)
    gap = wheel_t[j] - wheel_t[j - 1]
    covered = (imu_t >= wheel_t[0] - 0.5) & (imu_t <= wheel_t[-1] + 0.5) & (gap <= 1.0)
    ws = np.interp(imu_t, wheel_t, np.abs(wheel_v))
    still: NDArray[np.bool_] = np.where(covered, (ws < n.zupt_speed_m_s) & quiet, imu_still)
    return still


def degraded_intervals(
    gnss_t: F64, t_start: float, t_end: float, gap_s: float
) -> tuple[tuple[float, float], ...]:
    """Stretches after ``t_start`` with no valid fix for longer than ``gap_s``: (last fix,
    next fix), or (last fix, log end)."""
    ft = gnss_t[(gnss_t >= t_start) & (gnss_t <= t_end)]
    edges = np.r_[ft, t_end]
    d = np.diff(edges)
    return tuple((float(edges[i]), float(edges[i + 1])) for i in np.flatnonzero(d > gap_s))
