"""Sensor error models: a MEMS IMU, a wheel-speed sensor and a GNSS receiver.

Defaults are those of an automotive MEMS unit and a consumer single-frequency receiver
(see the "IMU error magnitudes" of the project's field notes). Each model draws from its own
``numpy.random.Generator``, so the same seed gives the same errors whatever the other sensors'
rates are.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields, replace

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

F64 = NDArray[np.float64]

DEG_H = np.pi / 180.0 / 3600.0
"""1 deg/h in rad/s"""
MG = 9.80665e-3
"""1 mg in m/s^2"""


def gauss_markov(
    rng: np.random.Generator, n: int, dt: float, sigma: float, tau: float, dims: int = 3
) -> F64:
    """(n, dims) stationary first-order Gauss-Markov samples (std ``sigma``, correlation time
    ``tau``), exact discretisation at step ``dt``."""
    w = rng.standard_normal((n, dims))
    if sigma == 0.0 or n == 0:
        return np.zeros((n, dims))
    a = np.exp(-dt / tau)
    x = w * (sigma * np.sqrt(1.0 - a * a))
    x[0] = w[0] * sigma
    samples: F64 = lfilter([1.0], [1.0, -a], x, axis=0)
    return samples


def quantise(x: F64, lsb: float) -> F64:
    return x if lsb <= 0 else np.round(x / lsb) * lsb


@dataclass(frozen=True)
class ImuErrorModel:
    """MEMS IMU errors, per axis. Biases are a turn-on constant (drawn once per seed) plus a
    first-order Gauss-Markov bias instability; white noise is angle / velocity random walk.
    Output is quantised to a power-of-two LSB (which also lets the bag compress)."""

    gyro_turn_on_bias_deg_h: float = 30.0
    """1-sigma of the constant gyro bias drawn at power-on"""
    gyro_bias_instability_deg_h: float = 5.0
    """1-sigma of the Gauss-Markov part of the gyro bias"""
    gyro_bias_tau_s: float = 300.0
    gyro_arw_deg_sqrt_h: float = 0.25
    gyro_scale_ppm: float = 1500.0
    """1-sigma of a constant scale-factor error drawn per axis"""
    accel_turn_on_bias_mg: float = 1.5
    accel_bias_instability_mg: float = 0.2
    accel_bias_tau_s: float = 300.0
    accel_vrw_m_s_sqrt_h: float = 0.1
    accel_scale_ppm: float = 1000.0
    gyro_lsb_rad_s: float = 2.0**-16
    """about 0.0009 deg/s"""
    accel_lsb_m_s2: float = 2.0**-12
    """about 0.025 mg"""

    @classmethod
    def perfect(cls) -> ImuErrorModel:
        """No errors at all (and no quantisation): the ideal IMU."""
        return cls(**{f.name: 0.0 for f in fields(cls)})


@dataclass(frozen=True)
class ImuErrors:
    """The errors one simulation drew; ``measured = (1 + scale) * ideal + bias + noise``."""

    gyro_turn_on_bias: F64
    """(3,) rad/s"""
    gyro_bias: F64
    """(N, 3) total gyro bias (turn-on + Gauss-Markov), rad/s"""
    gyro_scale: F64
    """(3,) scale-factor errors"""
    accel_turn_on_bias: F64
    """(3,) m/s^2"""
    accel_bias: F64
    """(N, 3) total accelerometer bias, m/s^2"""
    accel_scale: F64


def apply_imu_errors(
    model: ImuErrorModel, rng: np.random.Generator, rate_hz: float, gyro: F64, accel: F64
) -> tuple[F64, F64, ImuErrors]:
    """Measured gyro and accelerometer from the ideal ones; draws in a fixed order."""
    n = len(gyro)
    dt = 1.0 / rate_hz
    g_on = rng.standard_normal(3) * model.gyro_turn_on_bias_deg_h * DEG_H
    a_on = rng.standard_normal(3) * model.accel_turn_on_bias_mg * MG
    g_sf = rng.standard_normal(3) * model.gyro_scale_ppm * 1e-6
    a_sf = rng.standard_normal(3) * model.accel_scale_ppm * 1e-6
    g_gm = gauss_markov(
        rng, n, dt, model.gyro_bias_instability_deg_h * DEG_H, model.gyro_bias_tau_s
    )
    a_gm = gauss_markov(rng, n, dt, model.accel_bias_instability_mg * MG, model.accel_bias_tau_s)
    g_white = rng.standard_normal((n, 3)) * (
        model.gyro_arw_deg_sqrt_h * np.pi / 180.0 / 60.0 * np.sqrt(rate_hz)
    )
    a_white = rng.standard_normal((n, 3)) * (model.accel_vrw_m_s_sqrt_h / 60.0 * np.sqrt(rate_hz))
    g_bias = g_on + g_gm
    a_bias = a_on + a_gm
    gyro_m = quantise((1.0 + g_sf) * gyro + g_bias + g_white, model.gyro_lsb_rad_s)
    accel_m = quantise((1.0 + a_sf) * accel + a_bias + a_white, model.accel_lsb_m_s2)
    return gyro_m, accel_m, ImuErrors(g_on, g_bias, g_sf, a_on, a_bias, a_sf)


@dataclass(frozen=True)
class WheelErrorModel:
    """Wheel-speed sensor: the true forward speed times ``1 + scale_error``, plus white noise,
    quantised."""

    rate_hz: float = 50.0
    scale_error: float = 0.005
    """the (fixed, not drawn) relative scale error: tyre radius off by 0.5 %"""
    noise_m_s: float = 0.03
    lsb_m_s: float = 2.0**-8
    """about 0.004 m/s"""

    @classmethod
    def perfect(cls, rate_hz: float = 50.0) -> WheelErrorModel:
        return cls(rate_hz=rate_hz, scale_error=0.0, noise_m_s=0.0, lsb_m_s=0.0)


def apply_wheel_errors(model: WheelErrorModel, rng: np.random.Generator, speed: F64) -> F64:
    noise = rng.standard_normal(len(speed)) * model.noise_m_s
    return quantise((1.0 + model.scale_error) * speed + noise, model.lsb_m_s)


@dataclass(frozen=True)
class GnssErrorModel:
    """A consumer receiver: white noise plus a slowly wandering (Gauss-Markov) error, nothing
    in tunnels, and degraded fixes near the portals (multipath jumps held for about a second,
    with an inflated but still optimistic covariance)."""

    rate_hz: float = 5.0
    white_h_m: float = 0.3
    white_v_m: float = 0.6
    wander_h_m: float = 0.8
    wander_v_m: float = 1.5
    wander_tau_s: float = 60.0
    degraded_before_s: float = 8.0
    """degraded fixes this long before a tunnel entry"""
    degraded_after_s: float = 8.0
    """degraded fixes this long after reacquisition"""
    reacquisition_s: float = 2.0
    """no fix this long after a tunnel exit"""
    multipath_h_m: float = 3.0
    """1-sigma of the horizontal multipath jumps"""
    multipath_v_m: float = 5.0
    multipath_hold_s: float = 1.0
    portal_bias_h_m: float = 3.0
    """1-sigma of the slowly growing horizontal bias per degraded window (cuttings, walls)"""
    portal_bias_v_m: float = 5.0
    degraded_reported_h_m: float = 2.5
    """1-sigma the receiver reports for degraded fixes (it underestimates the jumps)"""

    @classmethod
    def perfect(cls, rate_hz: float = 5.0) -> GnssErrorModel:
        """Exact fixes (and no degradation) whenever the sky is open."""
        return replace(
            cls(rate_hz=rate_hz),
            white_h_m=0.0,
            white_v_m=0.0,
            wander_h_m=0.0,
            wander_v_m=0.0,
            degraded_before_s=0.0,
            degraded_after_s=0.0,
            reacquisition_s=0.0,
            multipath_h_m=0.0,
            multipath_v_m=0.0,
            portal_bias_h_m=0.0,
            portal_bias_v_m=0.0,
            degraded_reported_h_m=0.0,
        )

    @property
    def nominal_sigma_h_m(self) -> float:
        return float(np.hypot(self.white_h_m, self.wander_h_m))

    @property
    def nominal_sigma_v_m(self) -> float:
        return float(np.hypot(self.white_v_m, self.wander_v_m))


def gnss_errors(
    model: GnssErrorModel,
    rng: np.random.Generator,
    t: F64,
    windows: Sequence[tuple[float, float, float, float]] = (),
) -> tuple[F64, F64, NDArray[np.bool_]]:
    """ENU errors (N, 3), reported variances (N, 3) and the degraded mask at the fix times
    ``t`` (relative s).

    ``windows`` are the degraded intervals ``(start, end, weight_at_start, weight_at_end)``:
    inside them the multipath jumps are added, plus a per-window bias (a cutting's wall
    reflects the signal from one side) that grows linearly between the two weights, so the
    fixes drift away before a portal and come back after it.
    """
    n = len(t)
    dt = 1.0 / model.rate_hz
    white = rng.standard_normal((n, 3)) * np.array(
        [model.white_h_m, model.white_h_m, model.white_v_m]
    )
    wander_h = gauss_markov(rng, n, dt, model.wander_h_m, model.wander_tau_s, dims=2)
    wander_v = gauss_markov(rng, n, dt, model.wander_v_m, model.wander_tau_s, dims=1)
    err = white + np.column_stack([wander_h, wander_v])
    hold = np.floor(t / max(model.multipath_hold_s, 1e-9)).astype(np.int64)
    jumps = rng.standard_normal((int(hold.max(initial=0)) + 1, 3)) * np.array(
        [model.multipath_h_m, model.multipath_h_m, model.multipath_v_m]
    )
    bias = rng.standard_normal((len(windows), 3)) * np.array(
        [model.portal_bias_h_m, model.portal_bias_h_m, model.portal_bias_v_m]
    )
    degraded = np.zeros(n, bool)
    for k, (a, b, w0, w1) in enumerate(windows):
        inside = (t >= a) & (t < b)
        degraded |= inside
        w = w0 + (w1 - w0) * (t[inside] - a) / max(b - a, 1e-9)
        err[inside] += jumps[hold[inside]] + w[:, None] * bias[k]
    var_h = model.nominal_sigma_h_m**2
    var_v = model.nominal_sigma_v_m**2
    var = np.tile([max(var_h, 1e-4), max(var_h, 1e-4), max(var_v, 1e-4)], (n, 1))
    deg_var = [model.degraded_reported_h_m**2] * 2 + [(2.0 * model.degraded_reported_h_m) ** 2]
    var = np.where(degraded[:, None], np.maximum(var, deg_var), var)
    return err, var, degraded
