"""The run driver: methods, outages, consistency, checkpoint reuse, bad input, real logs."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from _synthetic_drive import FRAME, drive
from scipy.stats import chi2

from estimator.errors import LogError, RoutefuseError
from estimator.log import ImuData
from estimator.params import Params, with_values
from estimator.pipeline import open_inputs, run, run_methods
from estimator.route import Route
from estimator.sim import simulate

DATA = Path(__file__).resolve().parents[3] / ".." / "shared" / "data"

EPOCH_FIELDS = (
    "t",
    "position",
    "velocity",
    "attitude",
    "position_sigma",
    "yaw_sigma",
    "gnss_used",
    "degraded",
)


def _truth_en(log, frame, t):
    tr = frame.to_enu(log.truth.lat, log.truth.lon, log.truth.alt)
    return np.column_stack([np.interp(t, log.truth.t, tr[:, i]) for i in range(2)])


def _finite(r):
    e = r.epochs
    return all(np.all(np.isfinite(getattr(e, f))) for f in EPOCH_FIELDS[:6])


def _same_epochs(a, b):
    return all(np.array_equal(getattr(a.epochs, f), getattr(b.epochs, f)) for f in EPOCH_FIELDS)


def test_without_outage_baseline_and_proposed_are_identical():
    log, _, pt = drive(duration=90.0, gyro_noise=1e-3, accel_noise=0.02, gnss_sigma=0.3)
    route = Route(pt[:, :2])
    base = run(log, route, Params(), method="baseline", frame=FRAME)
    prop = run(log, route, Params(), method="proposed", frame=FRAME)
    assert base.degraded_intervals == ()
    assert prop.matches == ()
    assert _same_epochs(base, prop)
    assert not prop.epochs.degraded.any()


def test_injected_outage_is_a_degraded_interval_with_dead_reckoning():
    log, _, _ = drive(duration=120.0)
    r = run(log, None, Params(), method="baseline", frame=FRAME, outages=[(40.0, 80.0)])
    ((a, b),) = r.degraded_intervals
    assert a - r.t0 == pytest.approx(40.0, abs=0.11)
    assert b - r.t0 == pytest.approx(80.0, abs=0.11)
    e = r.epochs
    inside = (e.t - r.t0 > 40.2) & (e.t - r.t0 < 79.9)
    assert e.degraded[inside].all()
    assert not e.gnss_used[inside].any()
    assert e.gnss_used[~e.degraded].any()
    # perfect sensors: 40 s of dead reckoning stays within centimetres
    err = np.linalg.norm(e.position[:, :2] - _truth_en(log, FRAME, e.t), axis=1)
    assert err[inside].max() < 0.02
    # the covariance grows while GNSS is away
    assert e.position_sigma[inside][-1, 0] > 2 * e.position_sigma[inside][0, 0]


def test_position_nees_is_within_chi_square_bounds():
    """Monte-Carlo NEES of the horizontal position over eight simulated drives with sensor
    errors (GNSS wander, portal multipath, MEMS IMU, wheel scale). The slowest error, the GNSS
    wander, is correlated over about 60 s, so only epochs 60 s apart count as independent: the
    time-and-run mean of a 2-dof NEES then has chi2(2 n) / n bounds."""
    nees, n = [], 0.0
    for seed in range(8):
        sim = simulate("short_tunnel", seed=seed)
        log, frame = sim.log(), sim.frame
        r = run(log, None, Params(), method="baseline", frame=frame)
        e = r.epochs
        ok = e.t <= log.truth.t[-1]
        err = (e.position[:, :2] - _truth_en(log, frame, e.t))[ok]
        nees.append(np.sum((err / e.position_sigma[ok, :2]) ** 2, axis=1))
        n += log.duration_s / 60.0
    mean = float(np.mean(np.concatenate(nees)))
    n = int(n)
    lo, hi = chi2.ppf([0.005, 0.995], 2 * n) / n
    assert lo <= mean <= hi, (mean, lo, hi)


def test_proposed_uses_the_route_in_the_outage_and_beats_dead_reckoning(tunnel, tunnel_proposed):
    log, route, frame = tunnel
    base = run(log, route, Params(), method="baseline", frame=frame)
    prop = tunnel_proposed
    accepted = [m for m in prop.matches if m.accepted]
    assert accepted
    t_first = prop.degraded_intervals[0][0] + Params().trigger.min_outage_s
    assert all(m.t >= t_first - 0.02 for m in prop.matches)

    def rmse(r):
        e = r.epochs
        sel = e.degraded & (e.t <= log.truth.t[-1])
        d = e.position[sel, :2] - _truth_en(log, frame, e.t[sel])
        return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))

    assert rmse(prop) < rmse(base)
    for m in accepted:
        assert np.linalg.norm(m.correction) > 0
        np.testing.assert_allclose(m.innovation, m.pseudo_position - m.p_dr, atol=1e-9)
        # the record's epoch is the corrected state at the attempt
        e = prop.epochs
        assert e.t[m.epoch] == pytest.approx(m.t)
        np.testing.assert_allclose(e.position[m.epoch, :2], m.p_dr + m.correction, atol=1e-9)
    for m in prop.matches:
        if not m.accepted:
            np.testing.assert_array_equal(m.correction, 0.0)


def test_no_wheel_and_an_outage_to_the_end_stay_finite():
    log, _, pt = drive(
        duration=80.0, with_wheel=False, gyro_noise=1e-3, accel_noise=0.02, gnss_sigma=0.5
    )
    route = Route(pt[:, :2])
    for method in ("baseline", "proposed", "paper"):
        r = run(log, route, Params(), method=method, frame=FRAME, outages=[(50.0, 1000.0)])
        assert _finite(r)
        assert any("no wheel speed" in w for w in r.warnings)
        assert r.degraded_intervals[-1][1] == pytest.approx(log.t_end)


def test_non_finite_imu_samples_are_dropped_with_a_warning():
    log, _, _ = drive(duration=40.0)
    gyro = log.imu.gyro.copy()
    gyro[500:503] = np.nan
    bad = dataclasses.replace(log, imu=ImuData(t=log.imu.t, gyro=gyro, accel=log.imu.accel))
    r = run(bad, None, Params(), method="baseline", frame=FRAME)
    assert _finite(r)
    assert any("dropped 3 non-finite IMU samples" in w for w in r.warnings)


def test_a_diverging_filter_is_a_log_error_not_nan():
    log, _, _ = drive(duration=40.0)
    accel = log.imu.accel.copy()
    accel[2000:] = 1e250
    bad = dataclasses.replace(log, imu=ImuData(t=log.imu.t, gyro=log.imu.gyro, accel=accel))
    with pytest.raises(LogError, match=r"synthetic\.mcap: the filter diverged"):
        run(bad, None, Params(), method="baseline", frame=FRAME)


def test_bad_inputs_are_one_line_errors():
    log, _, _ = drive(duration=30.0)
    with pytest.raises(RoutefuseError, match="END must be after START"):
        run(log, None, Params(), method="baseline", frame=FRAME, outages=[(20.0, 10.0)])
    with pytest.raises(RoutefuseError, match="needs a route"):
        run(log, None, Params(), method="proposed", frame=FRAME)
    with pytest.raises(LogError, match="no valid GNSS fix outside the outages"):
        run(log, None, Params(), method="baseline", frame=FRAME, outages=[(-1.0, 100.0)])
    still = drive(duration=30.0, speed=0.0)[0]
    with pytest.raises(LogError, match="cannot align"):
        run(still, None, Params(), method="baseline", frame=FRAME)


def test_configured_heading_starts_at_the_first_fix():
    log, _, _ = drive(duration=40.0)
    yaw0 = np.degrees(0.3)  # the drive's heading at t = 0
    p = with_values(Params(), {"sensors.initial_heading_deg": yaw0})
    r = run(log, None, p, method="baseline", frame=FRAME)
    assert r.epochs.t[0] - r.t0 < 0.02
    auto = run(log, None, Params(), method="baseline", frame=FRAME)
    assert auto.epochs.t[0] > r.epochs.t[0]
    err = np.linalg.norm(r.epochs.position[:, :2] - _truth_en(log, FRAME, r.epochs.t), axis=1)
    assert err.max() < 0.05


def test_progress_is_reported_up_to_one(tunnel):
    log, route, frame = tunnel
    seen: list[float] = []
    run(log, route, Params(), method="proposed", frame=frame, progress=seen.append)
    assert len(seen) >= 3
    assert seen == sorted(seen)
    assert seen[-1] == 1.0


# --- real logs ------------------------------------------------------------------------------


def _load(name):
    path = DATA / name
    if not path.exists():
        pytest.skip(f"{path} not present (shared sample data)")
    from estimator.io import load_log

    return load_log(path)


def test_husky_bag_with_its_rotated_imu():
    log = _load("robot_localization/test1.bag")
    p = with_values(
        Params(),
        {
            "sensors.imu_roll_deg": 90.0,
            "sensors.imu_yaw_deg": -90.0,
            "noise.gyro_arw_deg_sqrt_h": 12.0,
            "noise.accel_vrw_m_s_sqrt_h": 3.0,
        },
    )
    for outages in ((), ((150.0, 200.0),)):
        r = run(log, None, p, method="baseline", outages=outages)
        assert _finite(r)
        e = r.epochs
        assert e.t[-1] == pytest.approx(log.t_end, abs=0.1)
        fixes = r.frame.to_enu(log.gnss.lat, log.gnss.lon, log.gnss.alt)[:, :2]
        est = np.column_stack([np.interp(log.gnss.t, e.t, e.position[:, i]) for i in range(2)])
        good = log.gnss.t > e.t[0]
        assert np.median(np.linalg.norm(est[good] - fixes[good], axis=1)) < 2.0
        # level and upright: the rotated IMU must not put gravity on a horizontal axis
        assert np.degrees(np.abs(e.attitude[:, :2])).max() < 10.0


def test_comma_bag_baseline_and_proposed_with_an_outage():
    log = _load("comma2k19/i280.mcap")
    from estimator.io.routefile import load_route
    from estimator.nav.frames import LocalFrame

    ok = log.gnss.valid
    frame = LocalFrame.at(log.gnss.lat[ok], log.gnss.lon[ok], log.gnss.alt[ok])
    route = load_route(DATA / "comma2k19" / "i280_route.geojson", frame)
    p = with_values(Params(), {"sensors.imu_pitch_deg": -3.8, "sensors.imu_yaw_deg": 0.9})
    out = [(20.0, 50.0)]
    base = run(log, route, p, method="baseline", frame=frame, outages=out)
    prop = run(log, route, p, method="proposed", frame=frame, outages=out)
    assert _finite(base) and _finite(prop)
    assert prop.matches
    lag = 0.1  # the truth stamps lag the sensors (see the log's NOTES)
    tr = frame.to_enu(log.truth.lat, log.truth.lon, log.truth.alt)

    def rmse(r):
        e = r.epochs
        d = e.position[e.degraded, :2] - np.column_stack(
            [np.interp(e.t[e.degraded], log.truth.t - lag, tr[:, i]) for i in range(2)]
        )
        return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))

    assert rmse(base) < 20.0
    assert rmse(prop) < rmse(base)


@pytest.mark.parametrize("with_wheel", [True, False])
def test_a_stop_in_an_outage_is_held_by_zero_velocity_updates(with_wheel):
    log, _, _ = drive(duration=110.0, stop=(50.0, 70.0), with_wheel=with_wheel)
    r = run(log, None, Params(), method="baseline", frame=FRAME, outages=[(40.0, 95.0)])
    e = r.epochs
    rel = e.t - r.t0
    stopped = (rel > 51.0) & (rel < 69.0)
    assert np.linalg.norm(e.velocity[stopped], axis=1).max() < 0.01
    err = np.linalg.norm(e.position[:, :2] - _truth_en(log, FRAME, e.t), axis=1)
    assert err[stopped].max() - err[stopped].min() < 0.05  # no drift while parked
    assert err[e.degraded].max() < 1.0  # 55 s without GNSS, perfect sensors


def test_cruising_without_wheel_speed_is_not_taken_for_a_stop():
    """A noise-free IMU on a smooth road looks as still as a parked car when the yaw rate
    crosses zero: the stop must not be believed while the filter is moving."""
    log, _, _ = drive(duration=60.0, with_wheel=False)
    r = run(log, None, Params(), method="baseline", frame=FRAME, outages=[(10.0, 55.0)])
    err = np.linalg.norm(r.epochs.position[:, :2] - _truth_en(log, FRAME, r.epochs.t), axis=1)
    # 45 s of IMU + NHC after 9 s of GNSS: 2 m measured; a false stop costs tens of metres
    assert err.max() < 5.0


def test_heading_observation_is_applied_and_recorded(tunnel, tunnel_proposed):
    log, route, frame = tunnel
    p = with_values(Params(), {"extensions.heading_observation": True})
    r = run(log, route, p, method="proposed", frame=frame)
    assert _finite(r)
    accepted = [m for m in r.matches if m.accepted]
    assert accepted
    for m in accepted:
        h = m.heading_observation
        assert h is not None
        assert h.yaw_rad == m.rotation_rad
        assert h.sigma_rad >= np.radians(0.1)
        # the update moves yaw towards the observation, never past it
        applied = h.correction_rad
        assert abs(applied) <= abs(m.rotation_rad) + 1e-12
        assert applied * m.rotation_rad >= 0
    assert all(m.heading_observation is None for m in tunnel_proposed.matches)
    again = run(log, route, p, method="proposed", frame=frame, reuse=tunnel_proposed)
    assert _same_epochs(again, r)


def test_max_turn_is_the_largest_heading_change_over_a_stretch():
    from estimator.pipeline.driver import max_turn as _max_turn_deg

    s = np.linspace(0.0, 1000.0, 401)
    straight = np.column_stack([s, np.zeros_like(s)])
    assert _max_turn_deg(straight, 250.0, 5.0) == pytest.approx(0.0, abs=1e-9)
    # 300 m straight, a 30 deg arc of R 500 m (262 m), then straight: 250 m see 28.6 deg at most
    radius, turn = 500.0, np.radians(30.0)
    a = np.linspace(0.0, turn, 200)
    arc = np.column_stack([300.0 + radius * np.sin(a), radius * (1 - np.cos(a))])
    end = arc[-1] + np.outer(np.linspace(0.0, 300.0, 100), [np.cos(turn), np.sin(turn)])
    bend = np.vstack([straight[:121], arc[1:], end[1:]])
    assert _max_turn_deg(bend, 250.0, 5.0) == pytest.approx(np.degrees(250.0 / radius), abs=1.0)
    assert _max_turn_deg(bend, 1000.0, 5.0) == pytest.approx(30.0, abs=1.0)


def test_overlapping_windows_count_their_along_track_evidence_once():
    """extensions.overlap_inflation: an accepted match's along-track variance is the same
    attempt's times the window length over the distance since the previous accepted match."""
    samples = Path(__file__).resolve().parents[3] / "sample_logs"
    inputs = open_inputs(samples / "monaco_tunnel.mcap", samples / "monaco_tunnel.route.geojson")
    p = with_values(Params(), {"extensions.overlap_inflation": True})
    runs = run_methods(inputs, Params(), methods=("proposed",))
    on = run_methods(inputs, p, methods=("proposed",))["proposed"]
    dist = np.r_[0.0, np.cumsum(np.hypot(*np.diff(on.epochs.position[:, :2], axis=0).T))]

    def along_var(m):
        t = np.array([m.normal[1], -m.normal[0]])
        return float(t @ m.obs_cov @ t)

    checked = 0
    previous = None
    for m in on.matches:
        if not m.accepted:
            continue
        if previous is not None and m.along_observed and m.fit is not None:
            moved = dist[m.epoch] - dist[previous.epoch]
            factor = max(m.window_length_m / max(moved, p.window.spacing_m), 1.0)
            assert factor > 3.0
            assert along_var(m) == pytest.approx(factor * m.fit.along_sigma_m**2, rel=0.15)
            checked += 1
        previous = m
    assert checked >= 3
    off = [m for m in runs["proposed"].matches if m.accepted and m.along_observed]
    assert off and all(along_var(m) == pytest.approx(m.fit.along_sigma_m**2, rel=0.05) for m in off)


def test_a_filter_that_refuses_most_of_its_fixes_says_so(tunnel, tunnel_proposed):
    from estimator.pipeline.driver import gnss_acceptance_warnings

    log, _, _ = tunnel
    run_ = tunnel_proposed
    assert gnss_acceptance_warnings(log, run_.epochs, run_.degraded_intervals) == ()
    used = run_.epochs.gnss_used.copy()
    used[np.flatnonzero(used)[::5]] = False  # a fifth more refused: still most
    most = dataclasses.replace(run_.epochs, gnss_used=used)
    assert gnss_acceptance_warnings(log, most, run_.degraded_intervals) == ()
    used[np.flatnonzero(used)[: int(0.8 * used.sum())]] = False
    few = dataclasses.replace(run_.epochs, gnss_used=used)
    (warning,) = gnss_acceptance_warnings(log, few, run_.degraded_intervals)
    assert warning.startswith("GNSS: the filter used only ") and "outside the outages" in warning
