"""A small, exact synthetic drive for the filter tests: level road, analytic speed and yaw,
IMU from the navigation model of ``estimator.nav.earth`` (so a perfect IMU integrates back
to the truth), optional white noise and constant biases."""

from __future__ import annotations

import numpy as np

from estimator.log import GnssData, ImuData, Log, TruthData, WheelData
from estimator.nav.earth import earth_rate_n, normal_gravity
from estimator.nav.frames import LocalFrame

FRAME = LocalFrame(48.0, 11.0, 500.0)
T0 = 1.7e9


def _stop_factor(t, stop, ramp=4.0):
    """1 while driving, 0 while stopped, cosine ramps of ``ramp`` s; and its derivative."""
    g = np.ones_like(t)
    gd = np.zeros_like(t)
    if stop is None:
        return g, gd
    s0, s1 = stop
    down = (t >= s0 - ramp) & (t < s0)
    x = np.pi * (t[down] - (s0 - ramp)) / ramp
    g[down] = 0.5 * (1 + np.cos(x))
    gd[down] = -0.5 * np.sin(x) * np.pi / ramp
    g[(t >= s0) & (t <= s1)] = 0.0
    up = (t > s1) & (t < s1 + ramp)
    x = np.pi * (t[up] - s1) / ramp
    g[up] = 0.5 * (1 - np.cos(x))
    gd[up] = 0.5 * np.sin(x) * np.pi / ramp
    return g, gd


def kinematics(
    t,
    *,
    speed: float = 12.0,
    yaw_amp: float = 0.8,
    yaw_period: float = 60.0,
    stop: tuple[float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """yaw, yaw rate, speed, acceleration at times ``t`` (s after the drive start). ``stop``:
    (start, end) of a standstill, entered and left with 4 s ramps (turning stops too)."""
    t = np.asarray(t, np.float64)
    w = 2 * np.pi / yaw_period
    ws = 2 * np.pi / 37.0
    yaw_rate = yaw_amp * w * np.cos(w * t)
    v = speed * (1 + 0.2 * np.sin(ws * t))
    v_dot = speed * 0.2 * ws * np.cos(ws * t)
    if stop is None:
        return 0.3 + yaw_amp * np.sin(w * t), yaw_rate, v, v_dot
    g, gd = _stop_factor(t, stop)
    tf = np.arange(0.0, float(np.max(t)) + 1.0, 1e-3)
    gf, _ = _stop_factor(tf, stop)
    rate_f = yaw_amp * w * np.cos(w * tf) * gf
    yaw_f = 0.3 + np.r_[0.0, np.cumsum(0.5 * (rate_f[1:] + rate_f[:-1]) * 1e-3)]
    return np.interp(t, tf, yaw_f), yaw_rate * g, v * g, v_dot * g + v * gd


def drive(
    *,
    duration: float = 120.0,
    imu_hz: float = 100.0,
    gnss_hz: float = 10.0,
    wheel_hz: float = 50.0,
    speed: float = 12.0,
    yaw_amp: float = 0.8,
    yaw_period: float = 60.0,
    seed: int = 0,
    gyro_noise: float = 0.0,
    accel_noise: float = 0.0,
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0),
    accel_bias: tuple[float, float, float] = (0.0, 0.0, 0.0),
    gnss_sigma: float = 0.0,
    gnss_cov_sigma: float = 0.5,
    wheel_sigma: float = 0.0,
    wheel_scale: float = 1.0,
    with_wheel: bool = True,
    stop: tuple[float, float] | None = None,
) -> tuple[Log, np.ndarray, np.ndarray]:
    """(log, truth times, truth ENU positions (N, 3)). Yaw = yaw_amp * sin(2 pi t / period),
    speed = speed * (1 + 0.2 sin(2 pi t / 37))."""
    rng = np.random.default_rng(seed)
    fine_dt = 1e-3
    tf = np.arange(0.0, duration + 1.0, fine_dt)

    def kin(t):
        return kinematics(t, speed=speed, yaw_amp=yaw_amp, yaw_period=yaw_period, stop=stop)

    yaw_f, _, v_f, _ = kin(tf)
    ve, vn = v_f * np.cos(yaw_f), v_f * np.sin(yaw_f)
    # Simpson-accurate cumulative integral on the fine grid
    pe = np.r_[0.0, np.cumsum(0.5 * (ve[1:] + ve[:-1]) * fine_dt)]
    pn = np.r_[0.0, np.cumsum(0.5 * (vn[1:] + vn[:-1]) * fine_dt)]

    def pos(t):
        return np.column_stack([np.interp(t, tf, pe), np.interp(t, tf, pn), np.zeros_like(t)])

    wie = earth_rate_n(FRAME.lat0)
    g = normal_gravity(FRAME.lat0, FRAME.h0)
    t_imu = np.arange(0.0, duration, 1.0 / imu_hz)
    yaw, yaw_rate, v, v_dot = kin(t_imu)
    c, s = np.cos(yaw), np.sin(yaw)
    vel = np.column_stack([v * c, v * s, np.zeros_like(v)])
    acc = np.column_stack(
        [v_dot * c - v * yaw_rate * s, v_dot * s + v * yaw_rate * c, np.zeros_like(v)]
    )
    f_n = acc + 2 * np.cross(wie, vel) + np.array([0.0, 0.0, g])
    # C_bn = Rz(-yaw)
    f_b = np.column_stack(
        [c * f_n[:, 0] + s * f_n[:, 1], -s * f_n[:, 0] + c * f_n[:, 1], f_n[:, 2]]
    )
    w_b = np.column_stack([c * wie[0] + s * wie[1], -s * wie[0] + c * wie[1], wie[2] + yaw_rate])
    n = len(t_imu)
    gyro = w_b + np.asarray(gyro_bias) + gyro_noise * rng.standard_normal((n, 3))
    accel = f_b + np.asarray(accel_bias) + accel_noise * rng.standard_normal((n, 3))

    t_g = np.arange(0.0, duration, 1.0 / gnss_hz) + 0.003
    pg = pos(t_g) + gnss_sigma * rng.standard_normal((len(t_g), 3)) * np.array([1, 1, 2])
    geo = FRAME.to_geodetic(pg)
    gnss = GnssData(
        t=T0 + t_g,
        lat=geo[:, 0],
        lon=geo[:, 1],
        alt=geo[:, 2],
        status=np.zeros(len(t_g), np.int8),
        cov_enu=np.tile(
            [gnss_cov_sigma**2, gnss_cov_sigma**2, (2 * gnss_cov_sigma) ** 2], (len(t_g), 1)
        ),
    )
    wheel = None
    if with_wheel:
        t_w = np.arange(0.0, duration, 1.0 / wheel_hz) + 0.001
        _, _, v_w, _ = kin(t_w)
        wheel = WheelData(
            t=T0 + t_w, speed=v_w / wheel_scale + wheel_sigma * rng.standard_normal(len(t_w))
        )
    t_tr = np.arange(0.0, duration, 0.05)
    ptr = pos(t_tr)
    geo_tr = FRAME.to_geodetic(ptr)
    truth = TruthData(
        t=T0 + t_tr, lat=geo_tr[:, 0], lon=geo_tr[:, 1], alt=geo_tr[:, 2], heading=kin(t_tr)[0]
    )
    log = Log(
        path="synthetic.mcap",
        imu=ImuData(t=T0 + t_imu, gyro=gyro, accel=accel),
        gnss=gnss,
        wheel=wheel,
        truth=truth,
    )
    return log, T0 + t_tr, ptr
