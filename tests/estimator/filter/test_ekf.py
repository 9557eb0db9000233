"""The compiled filter: rotations, covariance propagation, updates against dense numpy
references, pure strapdown integration, stop/resume invariance, and perfect sensors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _synthetic_drive import FRAME, T0, drive, kinematics

from estimator.filter import kernel, layout, propagation, quaternion, updates
from estimator.filter.engine import Filter, epochs_of
from estimator.filter.setup import prepare_inputs
from estimator.nav.rotation import dcm_from_euler
from estimator.params import Params
from estimator.pipeline import run
from estimator.sim import simulate


def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _random_cov(rng, n=layout.NE):
    a = rng.standard_normal((n, n))
    return a @ a.T + n * np.eye(n)


def _config(rng):
    cfg = np.zeros(layout.NC)
    cfg[layout.C_ARW2] = 1e-7
    cfg[layout.C_VRW2] = 1e-5
    cfg[layout.C_TAU_G] = 500.0
    cfg[layout.C_QBG] = 1e-12
    cfg[layout.C_TAU_A] = 700.0
    cfg[layout.C_QBA] = 1e-9
    cfg[layout.C_TAU_W] = 60.0
    cfg[layout.C_QW_H] = 0.02
    cfg[layout.C_QW_V] = 0.05
    cfg[layout.C_WIE : layout.C_WIE + 3] = rng.standard_normal(3) * 1e-4
    cfg[layout.C_SCALE_ON] = 1.0
    return cfg


def test_euler_quaternion_matches_the_simulator_convention():
    rng = np.random.default_rng(1)
    C = np.empty((3, 3))
    for _ in range(20):
        r, p, y = rng.uniform(-1.2, 1.2, 3)
        quaternion.quat_to_dcm(quaternion.euler_to_quat(r, p, y), C)
        np.testing.assert_allclose(C, dcm_from_euler(r, p, y)[0], atol=1e-12)
        np.testing.assert_allclose(quaternion.dcm_to_euler(C), (r, p, y), atol=1e-12)


@pytest.mark.parametrize("walk", [0.0, 3.5])
def test_covariance_propagation_equals_dense_phi_p_phi_t_plus_q(walk):
    """``walk``: the horizontal position's random walk (m^2/s) an outage takes after an exit
    beyond its sigmas (``extensions.exit_adapt``)."""
    rng = np.random.default_rng(2)
    P = _random_cov(rng)
    cfg = _config(rng)
    aux = np.zeros(layout.NA)
    aux[layout.A_POS_WALK] = walk
    T = 0.02
    Cb = dcm_from_euler(0.1, -0.05, 2.0)[0]
    fn = np.array([0.3, -0.2, 9.81])
    aux[layout.A_COV_T] = T
    aux[layout.A_COV_C : layout.A_COV_C + 9] = (Cb * T).ravel()
    aux[layout.A_COV_F : layout.A_COV_F + 3] = fn * T
    wz = 0.3
    aux[layout.A_COV_W : layout.A_COV_W + 3] = Cb[:, 2] * wz * T
    w = cfg[layout.C_WIE : layout.C_WIE + 3]
    F = np.zeros((layout.NE, layout.NE))
    F[0:3, 0:3] = -_skew(w)
    F[0:3, 9:12] = -Cb
    F[0:3, layout.E_GSF] = -Cb[:, 2] * wz
    F[3:6, 0:3] = -_skew(fn)
    F[3:6, 3:6] = -2 * _skew(w)
    F[3:6, 12:15] = -Cb
    F[6:9, 3:6] = np.eye(3)
    F[9:12, 9:12] = -np.eye(3) / cfg[layout.C_TAU_G]
    F[12:15, 12:15] = -np.eye(3) / cfg[layout.C_TAU_A]
    F[16:19, 16:19] = -np.eye(3) / cfg[layout.C_TAU_W]
    Phi = np.eye(layout.NE) + F * T
    q = np.zeros(layout.NE)
    q[0:3], q[3:6] = cfg[layout.C_ARW2], cfg[layout.C_VRW2]
    q[9:12], q[12:15] = cfg[layout.C_QBG], cfg[layout.C_QBA]
    q[16:18], q[18] = cfg[layout.C_QW_H], cfg[layout.C_QW_V]
    q[6:8] = walk
    expected = Phi @ P @ Phi.T + np.diag(q) * T
    got = P.copy()
    propagation.flush_covariance(got, aux, cfg)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)
    assert aux[layout.A_COV_T] == 0.0
    assert not aux[layout.A_COV_W : layout.A_COV_W + 3].any()
    np.testing.assert_array_equal(got, got.T)


@pytest.mark.parametrize("normal", [(0.0, 0.0), (0.6, -0.8)])
def test_pseudo_position_update_is_the_kalman_update(normal):
    """The optimal update of every estimated state; the lane-offset error (measured through
    ``-normal``) is only considered: no gain, its variance unchanged, the Joseph form."""
    rng = np.random.default_rng(3)
    P = _random_cov(rng) * 0.1
    cfg = _config(rng)
    x = np.zeros(layout.NX)
    x[layout.X_QUAT] = 1.0
    x[layout.X_POS : layout.X_POS + 3] = [10.0, -4.0, 1.0]
    x[layout.X_SCALE] = 1.0
    z = np.array([11.0, -3.0])
    R = np.array([[2.0, 0.3], [0.3, 0.5]])
    n = np.array(normal)
    H = np.zeros((2, layout.NE))
    H[0, layout.E_POS] = H[1, layout.E_POS + 1] = 1.0
    H[:, layout.E_LANE] = -n
    H[:, layout.E_MAP : layout.E_MAP + 2] = np.eye(2)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    K[layout.E_LANE :] = 0.0  # the considered states
    y = z - x[:2]
    dx = K @ y
    I_KH = np.eye(layout.NE) - K @ H
    P_exp = I_KH @ P @ I_KH.T + K @ R @ K.T
    considered = P[layout.E_LANE :, layout.E_LANE :].copy()
    aux = np.zeros(layout.NA)
    x0 = x.copy()
    res = updates.pseudo_position_update(x, P, aux, cfg, z, R, n, 1.0, np.zeros(2))
    np.testing.assert_allclose(res[:2], y)
    np.testing.assert_allclose(res[2:], dx[6:8], rtol=1e-12)
    np.testing.assert_allclose(x[:3] - x0[:3], dx[6:9], rtol=1e-12)
    np.testing.assert_allclose(x[layout.X_VEL : layout.X_VEL + 3], dx[3:6], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(P, P_exp, rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(P[layout.E_LANE :, layout.E_LANE :], considered)
    assert aux[layout.A_INFLATE] == 1.0


def test_a_pseudo_position_estimates_the_route_errors_when_the_bias_is_applied():
    """With the map bias applied (``offset.map_bias_estimated``), the lane-offset and map-bias
    errors get their optimal gain too, and their estimate accumulates in ``aux[A_ROUTE:]``."""
    rng = np.random.default_rng(4)
    P = _random_cov(rng) * 0.1
    cfg = _config(rng)
    x = np.zeros(layout.NX)
    x[layout.X_QUAT] = 1.0
    x[layout.X_SCALE] = 1.0
    z = np.array([1.5, -0.5])
    R = np.array([[2.0, 0.3], [0.3, 0.5]])
    n = np.array([0.6, 0.8])
    H = np.zeros((2, layout.NE))
    H[0, layout.E_POS] = H[1, layout.E_POS + 1] = 1.0
    H[:, layout.E_LANE] = -n
    H[:, layout.E_MAP : layout.E_MAP + 2] = np.eye(2)
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    K[layout.E_ROT] = 0.0  # the map's rotation error stays considered
    K[layout.E_GSF] = 0.0  # and so does the gyro's scale-factor error, always
    dx = K @ (z - x[:2])
    I_KH = np.eye(layout.NE) - K @ H
    P_exp = I_KH @ P @ I_KH.T + K @ R @ K.T
    aux = np.zeros(layout.NA)
    aux[layout.A_ROUTE_EST] = 1.0
    aux[layout.A_ROUTE : layout.A_ROUTE + 3] = [0.5, 1.0, -1.0]
    updates.pseudo_position_update(x, P, aux, cfg, z, R, n, 1.0, np.zeros(2))
    np.testing.assert_allclose(P, P_exp, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(
        aux[layout.A_ROUTE : layout.A_ROUTE + 3],
        np.array([0.5, 1.0, -1.0]) + dx[layout.E_LANE : layout.E_LANE + 3],
        rtol=1e-12,
    )
    # the same update with the bias not applied only considers them
    P2 = _random_cov(rng) * 0.1
    aux2 = np.zeros(layout.NA)
    considered = P2[layout.E_LANE :, layout.E_LANE :].copy()
    updates.pseudo_position_update(x.copy(), P2, aux2, cfg, z, R, n, 1.0, np.zeros(2))
    np.testing.assert_array_equal(P2[layout.E_LANE :, layout.E_LANE :], considered)
    np.testing.assert_array_equal(aux2[layout.A_ROUTE : layout.A_ROUTE + 3], 0.0)


def test_the_route_errors_start_as_the_position_error_through_the_gain_and_grow():
    rng = np.random.default_rng(7)
    P = _random_cov(rng)
    cfg = _config(rng)
    aux = np.zeros(layout.NA)
    aux[layout.A_ROUTE : layout.A_ROUTE + 3] = [0.3, -1.0, 2.0]
    before = P.copy()
    gain = rng.standard_normal((3, 2))
    cov = np.array([[1.0, 0.2, 0.0], [0.2, 9.0, 2.0], [0.0, 2.0, 4.0]])
    updates.clone_route_errors(P, aux, cfg, gain, cov, True)
    pos, route = slice(layout.E_POS, layout.E_POS + 2), slice(layout.E_LANE, layout.E_LANE + 3)
    np.testing.assert_allclose(
        P[route, : layout.E_LANE], gain @ before[pos, : layout.E_LANE], rtol=1e-12
    )
    np.testing.assert_allclose(
        P[route, route], gain @ before[pos, pos] @ gain.T + cov, rtol=1e-12, atol=1e-12
    )
    np.testing.assert_array_equal(P, P.T)
    np.testing.assert_array_equal(
        P[: layout.E_LANE, : layout.E_LANE], before[: layout.E_LANE, : layout.E_LANE]
    )
    np.testing.assert_array_equal(aux[layout.A_ROUTE : layout.A_ROUTE + 3], 0.0)
    assert aux[layout.A_ROUTE_EST] == 1.0
    bias = slice(layout.E_MAP, layout.E_MAP + 2)
    grown = np.diag(P[bias, bias]).copy()
    updates.grow_map_bias(P, 0.5)
    np.testing.assert_array_equal(np.diag(P[bias, bias]), grown + 0.5)


def test_the_lane_offset_error_starts_as_the_cross_track_position_error():
    rng = np.random.default_rng(5)
    P = _random_cov(rng)
    cfg = _config(rng)
    aux = np.zeros(layout.NA)
    n = np.array([-np.sin(0.4), np.cos(0.4)])
    before = P.copy()
    updates.clone_lane_offset(P, aux, cfg, n)
    pos = slice(layout.E_POS, layout.E_POS + 2)
    row = n @ before[pos]
    np.testing.assert_allclose(P[layout.E_LANE, : layout.E_LANE], row[: layout.E_LANE], rtol=1e-12)
    assert P[layout.E_LANE, layout.E_LANE] == pytest.approx(n @ before[pos, pos] @ n, rel=1e-12)
    np.testing.assert_array_equal(P, P.T)
    np.testing.assert_array_equal(
        P[: layout.E_LANE, : layout.E_LANE], before[: layout.E_LANE, : layout.E_LANE]
    )
    # a clone: the lane-offset error minus the cross-track position error has no variance
    d = np.zeros(layout.NE)
    d[layout.E_LANE] = 1.0
    d[pos] = -n
    assert d @ P @ d == pytest.approx(0.0, abs=1e-12)
    assert np.linalg.eigvalsh(P).min() > -1e-12


def test_attitude_injection_rotates_in_the_navigation_frame():
    x = np.zeros(layout.NX)
    x[layout.X_QUAT : layout.X_QUAT + 4] = quaternion.euler_to_quat(0.0, 0.0, 0.5)
    dx = np.zeros(layout.NE)
    dx[2] = 0.01
    updates.inject(x, dx)
    C = np.empty((3, 3))
    quaternion.quat_to_dcm(x[layout.X_QUAT : layout.X_QUAT + 4], C)
    assert quaternion.dcm_to_euler(C)[2] == pytest.approx(0.51, abs=1e-12)


def _truth_at(log, t):
    tr = FRAME.to_enu(log.truth.lat, log.truth.lon, log.truth.alt)
    return np.column_stack([np.interp(t, log.truth.t, tr[:, i]) for i in range(3)])


def test_pure_strapdown_with_a_perfect_imu_follows_the_truth():
    """No GNSS, no wheel, no aiding: the mechanisation alone, from the true initial state."""
    log, _, _ = drive(duration=60.0, imu_hz=100.0)
    p = Params()
    inp = prepare_inputs(log, p, FRAME, ())
    cfg = inp.cfg.copy()
    cfg[layout.C_AID_DT] = 1e9
    k0 = int(inp.idx0[layout.I_IMU]) - 1
    t0 = inp.imu_t[k0]
    x = inp.x0.copy()
    x[layout.X_POS : layout.X_POS + 3] = _truth_at(log, [t0])[0]
    yaw, _, speed, _ = kinematics(t0 - T0)
    x[layout.X_VEL : layout.X_VEL + 3] = [speed * np.cos(yaw), speed * np.sin(yaw), 0.0]
    x[layout.X_QUAT : layout.X_QUAT + 4] = quaternion.euler_to_quat(0.0, 0.0, yaw)
    aux, idx = inp.aux0.copy(), inp.idx0.copy()
    out = np.zeros((5000, layout.NO))
    empty = np.empty(0)
    status = kernel.run_until(
        inp.imu_t[-1],
        x,
        inp.P0.copy(),
        aux,
        idx,
        inp.imu_t,
        inp.gyro,
        inp.accel,
        np.zeros(len(inp.imu_t), bool),
        empty,
        empty,
        empty,
        np.empty((0, 3)),
        np.empty((0, 3)),
        cfg,
        out,
    )
    assert status == layout.STATUS_DONE
    n = idx[layout.I_OUT]
    err = out[:n, layout.O_POS : layout.O_POS + 3] - _truth_at(log, out[:n, layout.O_T])
    horizontal = np.hypot(err[:, 0], err[:, 1])
    # 59 s and 700 m of free inertial navigation: 0.2 mm measured
    assert horizontal.max() < 0.005, horizontal.max()
    assert np.abs(err[:, 2]).max() < 0.005


def _started(inp, log, n_rows):
    f = Filter(inp, source=log.path, t_start=log.t_start)
    f.alloc(n_rows)
    f.write_row()
    f.aux[layout.A_NEXT_OUT] = f.aux[layout.A_TIME] + inp.cfg[layout.C_OUT_DT]
    return f


def test_stopping_and_resuming_changes_nothing():
    log, _, _ = drive(
        duration=40.0, gyro_noise=1e-3, accel_noise=0.02, gnss_sigma=0.5, wheel_sigma=0.05
    )
    p = Params()
    inp = prepare_inputs(log, p, FRAME, ())
    one = _started(inp, log, 1000)
    one.advance(math.inf)
    many = _started(inp, log, 1000)
    for t in np.arange(inp.imu_t[0], inp.imu_t[-1] + 1.0, 0.37):
        many.advance(t)
    n = one.n_out
    assert n == many.n_out
    np.testing.assert_array_equal(one.out[:n], many.out[:n])
    np.testing.assert_array_equal(one.x, many.x)
    np.testing.assert_array_equal(one.P, many.P)


def test_output_rows_grow_when_the_buffer_is_full():
    log, _, _ = drive(duration=30.0)
    p = Params()
    inp = prepare_inputs(log, p, FRAME, ())
    f = _started(inp, log, 5)
    f.advance(math.inf)
    ref = run(log, None, p, method="baseline", frame=FRAME)
    assert f.n_out == len(ref.epochs)
    epochs = epochs_of(f.out, f.n_out, inp.degraded)
    np.testing.assert_array_equal(epochs.position, ref.epochs.position)


@pytest.mark.parametrize("seed", [0, 1])
def test_perfect_sensors_stay_on_truth(seed):
    sim = simulate("short_tunnel", seed=seed, perfect=True)
    log, frame = sim.log(), sim.frame
    r = run(log, None, Params(), method="baseline", frame=frame)
    e = r.epochs
    inside = e.t <= log.truth.t[-1]
    tr = frame.to_enu(log.truth.lat, log.truth.lon, log.truth.alt)
    truth = np.column_stack([np.interp(e.t, log.truth.t, tr[:, i]) for i in range(3)])
    err = np.linalg.norm((e.position - truth)[inside, :2], axis=1)
    assert r.degraded_intervals, "the scenario has a tunnel"
    assert e.degraded.any()
    assert err.max() < 0.05, err.max()
    assert err[e.degraded[inside]].max() < 0.05
    heading = np.interp(e.t, log.truth.t, np.unwrap(log.truth.heading))
    yaw_err = np.angle(np.exp(1j * (e.attitude[:, 2] - heading)))[inside]
    assert np.degrees(np.abs(yaw_err)).max() < 0.05


def test_the_outage_s_own_last_fix_does_not_end_its_walk():
    """An outage starts at its last fix, which lies between IMU samples on a real receiver
    and so is applied after the driver set the outage's walk (``extensions.exit_adapt``):
    that fix leaves the walk on; the next fix after it ends it. (The last fix ended it: on the
    Husky log with six 20 s outages the walk lasted one IMU step.)"""
    log, _, _ = drive(
        duration=40.0, gyro_noise=1e-3, accel_noise=0.02, gnss_sigma=0.5, wheel_sigma=0.05
    )
    inp = prepare_inputs(log, Params(), FRAME, ())
    k = int(np.searchsorted(inp.gnss_t, inp.gnss_t[0] + 20.0))
    t_a = float(inp.gnss_t[k])
    assert not np.isin(t_a, inp.imu_t)
    f = _started(inp, log, 1000)
    f.advance(t_a)
    assert f.idx[layout.I_GNSS] == k  # the outage's last fix is still to be applied
    ahead = f.snapshot()
    for walk_from, kept in ((t_a, 2.5), (t_a - 1.0, 0.0)):
        f.set_state(ahead)
        f.aux[layout.A_POS_WALK] = 2.5
        f.aux[layout.A_WALK_FROM] = walk_from
        f.advance(0.5 * (t_a + float(inp.gnss_t[k + 1])))
        assert f.idx[layout.I_GNSS] == k + 1
        assert f.aux[layout.A_POS_WALK] == kept
    f.advance(float(inp.gnss_t[k + 1]) + 1e-3)
    assert f.aux[layout.A_POS_WALK] == 0.0
