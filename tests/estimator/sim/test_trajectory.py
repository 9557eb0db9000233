"""The truth is self-consistent, and a perfect IMU integrated in the model of
:mod:`estimator.nav.earth` reproduces it."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.errors import ConfigError
from estimator.nav.earth import earth_rate_n, gravity_n, normal_gravity
from estimator.nav.rotation import body_rate_from_euler_rates, dcm_from_euler, euler_from_dcm
from estimator.sim import Road, Trajectory, simulate, straight, turn


def _hilly_road() -> Road:
    pieces = (
        straight(150, speed_m_s=15.0)
        + turn(90, 200, speed_m_s=12.0)
        + straight(300, speed_m_s=20.0, grade=0.04)
        + turn(-60, 300)
        + straight(500, grade=-0.02)
    )
    return Road(pieces, heading0=0.3)


def test_derivatives_match_finite_differences() -> None:
    traj = Trajectory(_hilly_road(), lat0_deg=43.7)
    t = np.linspace(0.5, traj.duration_s - 0.5, 700)
    h = 1e-4
    kp, km, k = traj.at(t + h), traj.at(t - h), traj.at(t)
    assert np.abs((kp.position - km.position) / (2 * h) - k.velocity).max() < 1e-5
    assert np.abs((kp.velocity - km.velocity) / (2 * h) - k.acceleration).max() < 1e-5
    assert np.abs((kp.rpy - km.rpy) / (2 * h) - k.rpy_rate).max() < 1e-6
    # the body rate of the Euler rates equals the one of the rotation matrices
    c = k.c_nb()
    w_skew = np.einsum("nji,njk->nik", c, (kp.c_nb() - km.c_nb()) / (2 * h))
    w_fd = np.column_stack([w_skew[:, 2, 1], w_skew[:, 0, 2], w_skew[:, 1, 0]])
    w = body_rate_from_euler_rates(
        k.rpy[:, 0], k.rpy[:, 1], k.rpy_rate[:, 0], k.rpy_rate[:, 1], k.rpy_rate[:, 2]
    )
    assert np.abs(w - w_fd).max() < 1e-7
    assert np.abs(k.rpy_rate[:, 2]).max() > 0.05  # it does turn


def test_body_velocity_is_forward_only_and_lane_offset_kept() -> None:
    road = _hilly_road()
    traj = Trajectory(road, lane_offset_m=-1.75)
    k = traj.at(np.linspace(0.0, traj.duration_s, 500))
    v_b = np.einsum("nji,nj->ni", k.c_nb(), k.velocity)
    np.testing.assert_allclose(v_b[:, 0], k.speed, atol=1e-9)
    assert np.abs(v_b[:, 1:]).max() < 1e-9
    # right of the centreline by 1.75 m everywhere
    rel = k.position[:, :2] - road.xy(k.sigma)
    psi = road.heading(k.sigma)
    left = -np.sin(psi) * rel[:, 0] + np.cos(psi) * rel[:, 1]
    np.testing.assert_allclose(left, -1.75, atol=1e-9)


def test_euler_round_trip_and_gravity() -> None:
    rng = np.random.default_rng(1)
    rpy = rng.uniform([-0.5, -0.5, -3.0], [0.5, 0.5, 3.0], (50, 3))
    c = dcm_from_euler(rpy[:, 0], rpy[:, 1], rpy[:, 2])
    np.testing.assert_allclose(euler_from_dcm(c), rpy, atol=1e-12)
    # yaw counter-clockwise from East, pitch nose up, roll right side down
    c1 = dcm_from_euler([0.0], [0.1], [np.pi / 2])[0]
    np.testing.assert_allclose(c1[:, 0], [0.0, np.cos(0.1), np.sin(0.1)], atol=1e-12)
    c2 = dcm_from_euler([0.1], [0.0], [0.0])[0]
    assert c2[2, 1] > 0  # the left axis rises
    assert normal_gravity(0.0) == pytest.approx(9.7803, abs=1e-4)
    assert normal_gravity(90.0) == pytest.approx(9.8322, abs=1e-4)


def _strapdown_rk4(
    f_b: np.ndarray, w_ib: np.ndarray, rate: float, c0, v0, p0, lat0: float, h0: float
):
    """RK4 in the fixed local-level ENU frame, a step of two samples (the middle one is the
    midpoint). Returns (C_nb, v, p) after the last full step."""
    omega = earth_rate_n(lat0)
    g = gravity_n(lat0, h0)

    def skew(v):
        return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])

    def deriv(c, v, p, f, w):
        return c @ skew(w - c.T @ omega), c @ f + g - 2.0 * np.cross(omega, v), v

    c, v, p = c0.copy(), v0.copy(), p0.copy()
    h = 2.0 / rate
    for i in range(0, len(f_b) - 2, 2):
        y = (c, v, p)
        k1 = deriv(*y, f_b[i], w_ib[i])
        k2 = deriv(*(a + 0.5 * h * b for a, b in zip(y, k1, strict=True)), f_b[i + 1], w_ib[i + 1])
        k3 = deriv(*(a + 0.5 * h * b for a, b in zip(y, k2, strict=True)), f_b[i + 1], w_ib[i + 1])
        k4 = deriv(*(a + h * b for a, b in zip(y, k3, strict=True)), f_b[i + 2], w_ib[i + 2])
        c, v, p = (
            a + h / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
            for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4, strict=True)
        )
        u, _, vt = np.linalg.svd(c)
        c = u @ vt
    return c, v, p


@pytest.fixture(scope="module")
def perfect_minute():
    return simulate("short_tunnel", perfect=True, imu_rate_hz=200.0, duration_s=60.0)


def test_perfect_imu_integrates_to_the_truth(perfect_minute) -> None:
    """One minute with turns, grade changes and speed changes, 200 Hz ideal IMU (gravity and
    Earth rate included): 0.04 mm measured, centimetres required."""
    sim = perfect_minute
    k = sim.truth
    lat0, _, h0 = sim.scenario.origin
    c, v, p = _strapdown_rk4(
        sim.imu.accel,
        sim.imu.gyro,
        200.0,
        k.c_nb()[0],
        k.velocity[0],
        k.position[0],
        lat0,
        h0,
    )
    last = 2 * ((len(k.t) - 1) // 2)
    assert k.t[last] - k.t[0] == pytest.approx(60.0)
    assert np.linalg.norm(p - k.position[last]) < 0.01
    assert np.linalg.norm(v - k.velocity[last]) < 0.002
    att = euler_from_dcm(c.T @ k.c_nb()[last])  # small rotation between the two
    assert np.abs(att).max() < 1e-5
    assert np.abs(k.rpy_rate[:, 2]).max() > 0.05


def test_a_gravity_or_earth_rate_mistake_is_caught(perfect_minute) -> None:
    """The integration test can fail: leaving out the Coriolis term costs 3.3 m here."""
    sim = perfect_minute
    k = sim.truth
    lat0, _, h0 = sim.scenario.origin
    c_nb = k.c_nb()
    # the specific force without the Coriolis term, as a wrong model would produce it
    coriolis_b = np.einsum("nji,nj->ni", c_nb, 2.0 * np.cross(earth_rate_n(lat0), k.velocity))
    _, _, p = _strapdown_rk4(
        sim.imu.accel - coriolis_b,
        sim.imu.gyro,
        200.0,
        c_nb[0],
        k.velocity[0],
        k.position[0],
        lat0,
        h0,
    )
    last = 2 * ((len(k.t) - 1) // 2)
    assert np.linalg.norm(p - k.position[last]) > 1.0


def test_curvature_must_be_continuous() -> None:
    with pytest.raises(ConfigError, match="curvature jumps"):
        Road((*straight(100), turn(90, 100)[1]))
