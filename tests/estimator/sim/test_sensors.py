"""The sensor errors a simulation draws have the configured statistics."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from estimator.sim import (
    GnssErrorModel,
    ImuErrorModel,
    WheelErrorModel,
    get_scenario,
    simulate,
)
from estimator.sim.sensors import (
    DEG_H,
    MG,
    apply_imu_errors,
    apply_wheel_errors,
    gauss_markov,
    gnss_errors,
)


def _allan_dev(x: np.ndarray, rate: float, tau: float) -> np.ndarray:
    """Non-overlapping Allan deviation per column at averaging time ``tau``."""
    m = round(tau * rate)
    n = len(x) // m
    means = x[: n * m].reshape(n, m, -1).mean(axis=1)
    return np.sqrt(0.5 * np.mean(np.diff(means, axis=0) ** 2, axis=0))


def _rng(seed: int) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(seed))


def test_gyro_and_accel_white_noise_match_arw_and_vrw() -> None:
    model = ImuErrorModel()
    rate = 100.0
    n = int(1800 * rate)  # half an hour at rest
    zeros = np.zeros((n, 3))
    gyro, accel, err = apply_imu_errors(model, _rng(3), rate, zeros, zeros)
    # Allan deviation at 1 s: the random walk dominates (bias instability is ~20x smaller)
    arw = _allan_dev(gyro - err.gyro_bias, rate, 1.0) / (np.pi / 180 / 60)  # deg/sqrt(h)
    vrw = _allan_dev(accel - err.accel_bias, rate, 1.0) * 60.0  # m/s/sqrt(h)
    np.testing.assert_allclose(arw, model.gyro_arw_deg_sqrt_h, rtol=0.05)
    np.testing.assert_allclose(vrw, model.accel_vrw_m_s_sqrt_h, rtol=0.05)
    # the same from the raw output (bias included) at 1 s, still within 10 %
    arw_raw = _allan_dev(gyro, rate, 1.0) / (np.pi / 180 / 60)
    np.testing.assert_allclose(arw_raw, model.gyro_arw_deg_sqrt_h, rtol=0.1)
    # and the mean of the output is the drawn bias
    np.testing.assert_allclose(
        gyro.mean(axis=0), err.gyro_bias.mean(axis=0), atol=3 * 7.3e-5 / np.sqrt(1800)
    )


def test_turn_on_biases_have_the_configured_spread() -> None:
    model = ImuErrorModel()
    g_on, a_on = [], []
    for seed in range(300):
        _, _, err = apply_imu_errors(model, _rng(seed), 100.0, np.zeros((2, 3)), np.zeros((2, 3)))
        g_on.append(err.gyro_turn_on_bias)
        a_on.append(err.accel_turn_on_bias)
    g_std = np.std(np.array(g_on)) / DEG_H
    a_std = np.std(np.array(a_on)) / MG
    assert g_std == pytest.approx(model.gyro_turn_on_bias_deg_h, rel=0.1)
    assert a_std == pytest.approx(model.accel_turn_on_bias_mg, rel=0.1)


def test_gauss_markov_is_stationary_with_the_right_correlation() -> None:
    sigma, tau, dt = 5.0, 300.0, 30.0
    x = gauss_markov(_rng(7), 400, dt, sigma, tau, dims=500)
    assert np.std(x[0]) == pytest.approx(sigma, rel=0.1)
    assert np.std(x[-1]) == pytest.approx(sigma, rel=0.1)
    lag1 = np.mean(x[1:] * x[:-1]) / np.mean(x * x)
    assert lag1 == pytest.approx(np.exp(-dt / tau), abs=0.01)


def test_gyro_bias_measured_over_a_drive_matches_the_drawn_one() -> None:
    """Over a simulated drive, measured minus (scaled) ideal gyro averages to the drawn bias
    (turn-on plus Gauss-Markov), whatever the motion."""
    sim = simulate("short_tunnel", seed=11)
    meas = sim.imu.gyro - (1.0 + sim.imu_errors.gyro_scale) * sim.ideal_gyro
    drawn = sim.imu_errors.gyro_bias.mean(axis=0)
    white = 0.25 * np.pi / 180 / 60 / np.sqrt(sim.duration_s)
    np.testing.assert_allclose(meas.mean(axis=0), drawn, atol=4 * white)
    assert np.abs(sim.imu_errors.gyro_turn_on_bias).max() > 5 * white  # not trivially zero


def test_output_is_quantised_and_perfect_is_exact() -> None:
    model = ImuErrorModel()
    x = np.linspace(-1.0, 1.0, 3000).reshape(1000, 3)
    gyro, accel, _ = apply_imu_errors(model, _rng(1), 100.0, x, x + 9.8)
    np.testing.assert_array_equal(gyro, np.round(gyro / model.gyro_lsb_rad_s) * 2.0**-16)
    np.testing.assert_array_equal(accel, np.round(accel / model.accel_lsb_m_s2) * 2.0**-12)
    gyro_p, accel_p, err = apply_imu_errors(ImuErrorModel.perfect(), _rng(1), 100.0, x, x + 9.8)
    np.testing.assert_array_equal(gyro_p, x)
    np.testing.assert_array_equal(accel_p, x + 9.8)
    assert not err.gyro_bias.any()


def test_wheel_scale_error_and_noise() -> None:
    model = WheelErrorModel()
    speed = np.linspace(5.0, 30.0, 100_000)
    meas = apply_wheel_errors(model, _rng(2), speed)
    slope, intercept = np.polyfit(speed, meas, 1)
    assert slope - 1.0 == pytest.approx(model.scale_error, abs=2e-4)
    assert abs(intercept) < 0.01
    resid = meas - slope * speed - intercept
    assert np.std(resid) == pytest.approx(
        np.hypot(model.noise_m_s, model.lsb_m_s / 12**0.5), rel=0.05
    )


def test_wheel_scale_error_in_a_simulated_drive() -> None:
    sim = simulate("short_tunnel", seed=5)
    truth_speed = sim.trajectory.at(sim.wheel.t - sim.t0).speed
    ratio = np.sum(sim.wheel.speed * truth_speed) / np.sum(truth_speed**2)
    assert ratio - 1.0 == pytest.approx(sim.scenario.wheel.scale_error, abs=2e-4)


def test_gnss_errors_nominal_and_degraded() -> None:
    model = GnssErrorModel()
    t = np.arange(0.0, 20_000.0, 1.0 / model.rate_hz)
    windows = [(a, a + 10.0, 1.0, 1.0) for a in np.arange(0.0, 20_000.0, 100.0)]
    err, var, degraded = gnss_errors(model, _rng(9), t, windows)
    assert degraded.sum() == 10 * 200 * model.rate_hz
    open_err = err[~degraded]
    assert np.std(open_err[:, :2]) == pytest.approx(model.nominal_sigma_h_m, rel=0.1)
    assert np.std(open_err[:, 2]) == pytest.approx(model.nominal_sigma_v_m, rel=0.15)
    np.testing.assert_allclose(var[~degraded, 0], model.nominal_sigma_h_m**2)
    # degraded: metre-level jumps held for a second, inflated (but optimistic) covariance
    deg_h = np.std(err[degraded, :2])
    expected = np.sqrt(
        model.nominal_sigma_h_m**2 + model.multipath_h_m**2 + model.portal_bias_h_m**2
    )
    assert deg_h == pytest.approx(expected, rel=0.1)
    assert np.all(var[degraded, 0] == model.degraded_reported_h_m**2)
    assert model.degraded_reported_h_m < deg_h


def test_gnss_outage_encodings() -> None:
    for outage in ("no_fix", "silent"):
        sc = replace(get_scenario("short_tunnel"), gnss_outage=outage)
        sim = simulate(sc, seed=0)
        ((a, b),) = sim.tunnels
        inside = (sim.gnss.t >= a) & (sim.gnss.t < b)
        assert not sim.gnss.valid[inside].any()
        if outage == "no_fix":
            assert inside.sum() == pytest.approx((b - a) * sc.gnss.rate_hz, abs=1)
            assert np.all(sim.gnss.status[inside] == -1)
            assert np.all(np.isnan(sim.gnss.lat[inside]))
        else:
            assert inside.sum() == 0
            assert np.all(sim.gnss.valid)
        # reacquisition: still nothing right after the exit, then degraded fixes
        after = (sim.gnss.t >= b) & (sim.gnss.t < b + sc.gnss.reacquisition_s)
        assert not sim.gnss.valid[after].any()
        ((d0, d1),) = [iv for iv in sim.gnss_degraded if iv[0] >= b]
        deg = (sim.gnss.t >= d0) & (sim.gnss.t < d1)
        assert deg.sum() > 0 and np.all(sim.gnss.valid[deg])
        assert np.all(sim.gnss.cov_enu[deg, 0] > sc.gnss.nominal_sigma_h_m**2)


def test_portal_bias_ramps_in_and_out() -> None:
    model = GnssErrorModel(
        white_h_m=0.0,
        white_v_m=0.0,
        wander_h_m=0.0,
        wander_v_m=0.0,
        multipath_h_m=0.0,
        multipath_v_m=0.0,
    )
    t = np.arange(0.0, 40.0, 0.2)
    err, _, degraded = gnss_errors(
        model, _rng(4), t, [(10.0, 18.0, 0.0, 1.0), (25.0, 33.0, 1.0, 0.0)]
    )
    assert not err[~degraded].any()
    before = err[(t >= 10.0) & (t < 18.0)]
    np.testing.assert_allclose(before[0], 0.0, atol=1e-12)
    steps = np.diff(before, axis=0)
    np.testing.assert_allclose(steps, np.broadcast_to(steps[0], steps.shape), atol=1e-12)
    assert np.linalg.norm(before[-1]) > 0.1
    after = err[(t >= 25.0) & (t < 33.0)]
    assert np.linalg.norm(after[0]) > np.linalg.norm(after[-1])
