"""Drives the tunnel simulator cannot make (a stop of minutes, a U-turn, a detour off the
route), built directly as :class:`Log` arrays: a level road, speed and yaw rate piecewise
linear in time, the IMU from the navigation model of ``estimator.nav.earth`` (so a perfect
IMU integrates back to the truth), MEMS-like noise and biases, GNSS with outages."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimator.log import GnssData, ImuData, Log, WheelData
from estimator.nav.earth import earth_rate_n, normal_gravity
from estimator.nav.frames import LocalFrame
from estimator.route import Route

F64 = NDArray[np.float64]
FRAME = LocalFrame(46.0, 8.0, 400.0)
T0 = 1_700_000_000.0
FINE_DT = 1e-3


@dataclass(frozen=True)
class FaultDrive:
    log: Log
    frame: LocalFrame
    t: F64
    """truth times, log clock"""
    xy: F64
    """(N, 2) truth EN positions in ``frame``"""
    yaw: F64
    speed: F64

    def truth_at(self, t: F64 | float) -> F64:
        tt = np.atleast_1d(np.asarray(t, np.float64))
        return np.column_stack(
            [np.interp(tt, self.t, self.xy[:, 0]), np.interp(tt, self.t, self.xy[:, 1])]
        )


def _pwl(knots: Sequence[tuple[float, float]], t: F64) -> tuple[F64, F64]:
    """Value and slope of a piecewise-linear function of time."""
    kt = np.array([k[0] for k in knots])
    kv = np.array([k[1] for k in knots])
    value = np.interp(t, kt, kv)
    i = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, len(kt) - 2)
    slope = (kv[i + 1] - kv[i]) / np.maximum(kt[i + 1] - kt[i], 1e-12)
    slope = np.where((t < kt[0]) | (t >= kt[-1]), 0.0, slope)
    return value, slope


def make_drive(
    speed: Sequence[tuple[float, float]],
    yaw_rate_deg_s: Sequence[tuple[float, float]],
    *,
    duration: float,
    outages: Sequence[tuple[float, float]] = (),
    yaw0_deg: float = 30.0,
    seed: int = 0,
    imu_hz: float = 100.0,
    gnss_hz: float = 5.0,
    wheel_hz: float = 50.0,
    gyro_bias_deg_h: tuple[float, float, float] = (10.0, -8.0, 20.0),
    accel_bias_mg: tuple[float, float, float] = (1.0, -1.0, 0.5),
    gyro_noise: float = 2e-4,
    accel_noise: float = 0.01,
    gnss_sigma: float = 0.4,
    wheel_sigma: float = 0.03,
) -> FaultDrive:
    """Speed (m/s) and yaw rate (deg/s) as (t, value) knots, t in s after the start.
    ``outages``: (start, end) s where the receiver reports NO_FIX (a tunnel)."""
    rng = np.random.default_rng(seed)
    tf = np.arange(0.0, duration + 1.0, FINE_DT)
    r_f = np.radians(_pwl(yaw_rate_deg_s, tf)[0])
    yaw_f = np.radians(yaw0_deg) + np.r_[0.0, np.cumsum(0.5 * (r_f[1:] + r_f[:-1]) * FINE_DT)]
    v_f = _pwl(speed, tf)[0]
    ve, vn = v_f * np.cos(yaw_f), v_f * np.sin(yaw_f)
    pe = np.r_[0.0, np.cumsum(0.5 * (ve[1:] + ve[:-1]) * FINE_DT)]
    pn = np.r_[0.0, np.cumsum(0.5 * (vn[1:] + vn[:-1]) * FINE_DT)]

    def at(t: F64) -> tuple[F64, F64, F64, F64, F64]:
        yaw = np.interp(t, tf, yaw_f)
        v, v_dot = _pwl(speed, t)
        rate = np.radians(_pwl(yaw_rate_deg_s, t)[0])
        return np.interp(t, tf, pe), np.interp(t, tf, pn), yaw, v, np.c_[v_dot, rate]

    wie = earth_rate_n(FRAME.lat0)
    g = normal_gravity(FRAME.lat0, FRAME.h0)
    t_imu = np.arange(0.0, duration, 1.0 / imu_hz)
    _, _, yaw, v, dd = at(t_imu)
    v_dot, rate = dd[:, 0], dd[:, 1]
    c, s = np.cos(yaw), np.sin(yaw)
    vel = np.column_stack([v * c, v * s, np.zeros_like(v)])
    acc = np.column_stack([v_dot * c - v * rate * s, v_dot * s + v * rate * c, np.zeros_like(v)])
    f_n = acc + 2 * np.cross(wie, vel) + np.array([0.0, 0.0, g])
    f_b = np.column_stack(
        [c * f_n[:, 0] + s * f_n[:, 1], -s * f_n[:, 0] + c * f_n[:, 1], f_n[:, 2]]
    )
    w_b = np.column_stack([c * wie[0] + s * wie[1], -s * wie[0] + c * wie[1], wie[2] + rate])
    n = len(t_imu)
    bg = np.radians(np.asarray(gyro_bias_deg_h)) / 3600.0
    ba = np.asarray(accel_bias_mg) * 9.80665e-3
    gyro = w_b + bg + gyro_noise * rng.standard_normal((n, 3))
    accel = f_b + ba + accel_noise * rng.standard_normal((n, 3))

    t_g = np.arange(0.0, duration, 1.0 / gnss_hz) + 0.002
    e, nn, *_ = at(t_g)
    enu = np.column_stack([e, nn, np.zeros_like(e)])
    enu += gnss_sigma * rng.standard_normal(enu.shape) * np.array([1.0, 1.0, 2.0])
    geo = FRAME.to_geodetic(enu)
    status = np.zeros(len(t_g), np.int8)
    for a, b in outages:
        status[(t_g >= a) & (t_g <= b)] = -1
    lat, lon, alt = (np.where(status < 0, np.nan, geo[:, i]) for i in range(3))
    cov = np.tile([gnss_sigma**2, gnss_sigma**2, (2 * gnss_sigma) ** 2], (len(t_g), 1))
    cov[status < 0] = np.nan
    gnss = GnssData(T0 + t_g, lat, lon, alt, status, cov)

    t_w = np.arange(0.0, duration, 1.0 / wheel_hz) + 0.001
    v_w = _pwl(speed, t_w)[0]
    wheel = WheelData(T0 + t_w, v_w + wheel_sigma * rng.standard_normal(len(t_w)))

    t_tr = np.arange(0.0, duration, 0.05)
    e, nn, yaw_tr, v_tr, _ = at(t_tr)
    log = Log("<fault drive>", ImuData(T0 + t_imu, gyro, accel), gnss, wheel)
    return FaultDrive(log, FRAME, T0 + t_tr, np.column_stack([e, nn]), yaw_tr, v_tr)


def route_along(
    drive: FaultDrive,
    t0: float,
    t1: float,
    *,
    offset_m: float = 1.75,
    spacing_m: float = 25.0,
    extend_m: float = 0.0,
) -> Route:
    """An SD-map route: the truth path between two times (s after start), shifted ``offset_m``
    to the LEFT of the driven lane, with a vertex every ``spacing_m`` and straight extensions."""
    sel = (drive.t >= T0 + t0) & (drive.t <= T0 + t1)
    xy, yaw = drive.xy[sel], drive.yaw[sel]
    left = np.column_stack([-np.sin(yaw), np.cos(yaw)])
    xy = xy + offset_m * left
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    keep = np.searchsorted(s, np.arange(0.0, s[-1], spacing_m))
    pts = np.vstack([xy[keep], xy[-1:]])
    if extend_m > 0:
        d0 = pts[0] - pts[1]
        d1 = pts[-1] - pts[-2]
        pts = np.vstack(
            [pts[0] + extend_m * d0 / np.hypot(*d0), pts, pts[-1] + extend_m * d1 / np.hypot(*d1)]
        )
    return Route(pts, name="fault route", source="<fault route>")
