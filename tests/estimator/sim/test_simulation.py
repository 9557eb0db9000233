"""Whole simulations: determinism, bag and route read-back, and what the scenarios promise."""

from __future__ import annotations

import json

import numpy as np
import pytest

from estimator.errors import ConfigError
from estimator.io import load_log
from estimator.io.routefile import load_route
from estimator.nav.frames import LocalFrame
from estimator.route import Route
from estimator.sim import SCENARIOS, Trajectory, get_scenario, polyline_scenario, simulate

SAMPLES = ("long_tunnel", "spiral_tunnel", "multi_tunnel", "monaco_tunnel")


def test_same_seed_same_bytes(tmp_path) -> None:
    paths = []
    for run in ("a", "b"):
        sim = simulate("short_tunnel", seed=4, duration_s=20.0)
        paths.append(sim.write(tmp_path / run))
    (bag_a, route_a), (bag_b, route_b) = paths
    assert bag_a.read_bytes() == bag_b.read_bytes()
    assert route_a.read_bytes() == route_b.read_bytes()
    other = simulate("short_tunnel", seed=5, duration_s=20.0)
    bag_c, _ = other.write(tmp_path / "c")
    assert bag_c.read_bytes() != bag_a.read_bytes()


def test_seed_streams_are_independent_of_rates() -> None:
    """Changing the IMU rate leaves the GNSS and wheel errors of a seed unchanged."""
    a = simulate("short_tunnel", seed=2, duration_s=10.0)
    b = simulate("short_tunnel", seed=2, duration_s=10.0, imu_rate_hz=200.0)
    np.testing.assert_array_equal(a.gnss.lat, b.gnss.lat)
    np.testing.assert_array_equal(a.wheel.speed, b.wheel.speed)
    assert len(b.imu.t) == 2 * len(a.imu.t) - 1


def test_bag_reads_back_through_the_loader(tmp_path) -> None:
    sim = simulate("short_tunnel", seed=1)
    bag, _ = sim.write(tmp_path)
    log = load_log(bag, cache_dir=tmp_path / "cache")
    assert len(log.imu.t) == len(sim.imu.t)
    np.testing.assert_allclose(log.imu.t, sim.imu.t, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(log.imu.gyro, sim.imu.gyro)
    np.testing.assert_array_equal(log.imu.accel, sim.imu.accel)
    np.testing.assert_array_equal(log.wheel.speed, sim.wheel.speed)
    assert len(log.gnss.t) == len(sim.gnss.t)
    np.testing.assert_array_equal(log.gnss.valid, sim.gnss.valid)
    ok = sim.gnss.valid
    np.testing.assert_array_equal(log.gnss.lat[ok], sim.gnss.lat[ok])
    np.testing.assert_allclose(log.gnss.cov_enu[ok], sim.gnss.cov_enu[ok])
    assert log.truth is not None
    np.testing.assert_array_equal(log.truth.lat, sim.truth_fix.lat)
    dh = np.angle(np.exp(1j * (log.truth.heading - sim.truth_fix.heading)))
    assert np.abs(dh).max() < 1e-9
    # no NaN reaches the estimator-facing streams
    assert np.all(np.isfinite(log.imu.gyro)) and np.all(np.isfinite(log.imu.accel))


def test_route_reads_back_and_lies_left_of_the_lane(tmp_path) -> None:
    sim = simulate("short_tunnel", seed=0)
    _, route_path = sim.write(tmp_path)
    doc = json.loads(route_path.read_text())
    (feature,) = doc["features"]
    assert feature["geometry"]["type"] == "LineString"
    assert feature["properties"]["lateral_offset_m"] == pytest.approx(1.75)
    route = load_route(route_path, sim.frame)
    np.testing.assert_allclose(route.xy, sim.route_xy, atol=2e-3)
    proj = route.project(sim.truth.position[:, :2])
    # the lane is 1.75 m right of the centreline; the map cuts corners by decimetres
    assert np.median(proj.lateral) == pytest.approx(-1.75, abs=0.05)
    assert np.abs(proj.lateral + 1.75).max() < 0.5
    # the route reaches 200 m beyond both ends of the drive
    assert proj.s.min() == pytest.approx(200.0, abs=1.0)
    assert route.length - proj.s.max() == pytest.approx(200.0, abs=1.0)


def test_map_bias_shifts_the_route() -> None:
    from dataclasses import replace

    sc = get_scenario("short_tunnel")
    biased = replace(sc, route=replace(sc.route, bias_enu_m=(2.0, -1.0)))
    a = simulate(sc, duration_s=5.0)
    b = simulate(biased, duration_s=5.0)
    np.testing.assert_allclose(b.route_xy - a.route_xy, np.tile([2.0, -1.0], (len(a.route_xy), 1)))


@pytest.mark.parametrize("name", SAMPLES)
def test_sample_scenarios_keep_their_promises(name) -> None:
    """>= 60 s of open sky with turns before the first tunnel, open sky after the last one,
    |a| < 2 m/s^2, a few minutes long."""
    sc = get_scenario(name)
    road = sc.road()
    traj = Trajectory(road, lane_offset_m=sc.lane_offset_m, lat0_deg=sc.origin[0])
    tunnels = [traj.time_at([a, b]) for a, b in road.tunnel_intervals()]
    first_entry = tunnels[0][0]
    last_exit = tunnels[-1][1]
    assert first_entry >= 60.0
    assert traj.duration_s - last_exit >= 30.0
    assert 180.0 <= traj.duration_s <= 540.0
    k = traj.at(np.arange(0.0, traj.duration_s, 0.1))
    assert np.linalg.norm(k.acceleration, axis=1).max() < 2.0
    before = k.t < first_entry
    heading_change = np.ptp(np.unwrap(k.heading[before]))
    assert np.degrees(heading_change) > 45.0
    assert np.degrees(np.abs(k.rpy[:, :2])).max() < 5.0


def test_duration_scale_stretches_the_straights() -> None:
    sc = get_scenario("long_tunnel")
    short, full = sc.scaled(0.2).road(), sc.road()

    def tunnel_parts(pieces):
        straights = sum(p.length_m for p in pieces if p.tunnel and p.scalable)
        return straights, sum(p.length_m for p in pieces if p.tunnel and not p.scalable)

    (s_short, t_short), (s_full, t_full) = tunnel_parts(short.pieces), tunnel_parts(full.pieces)
    assert s_short == pytest.approx(0.2 * s_full) and t_short == t_full
    assert sum(b - a for a, b in short.tunnel_intervals()) == pytest.approx(s_short + t_short)
    # the turns keep their angles
    assert abs(short.heading(short.length) - full.heading(full.length))[0] < 1e-12


def test_long_drive_for_benchmarks() -> None:
    sc = get_scenario("long_drive_10min")
    traj = Trajectory(sc.road(), lat0_deg=sc.origin[0])
    assert 570.0 < traj.duration_s < 630.0
    assert len(sc.road().tunnel_intervals()) >= 1


def test_unknown_scenario_and_bad_options() -> None:
    with pytest.raises(ConfigError, match="unknown scenario 'nope'"):
        simulate("nope")
    with pytest.raises(ConfigError, match="IMU rate"):
        simulate("short_tunnel", imu_rate_hz=0.0)
    assert set(SAMPLES) <= set(SCENARIOS)


def test_perfect_sensors() -> None:
    sim = simulate("short_tunnel", perfect=True, duration_s=30.0)
    np.testing.assert_array_equal(sim.imu.gyro, sim.ideal_gyro)
    np.testing.assert_array_equal(sim.imu.accel, sim.ideal_accel)
    truth = sim.trajectory.at(np.round(sim.gnss.t[sim.gnss.valid] - sim.t0, 6)).position
    fixes = sim.frame.to_enu(
        sim.gnss.lat[sim.gnss.valid], sim.gnss.lon[sim.gnss.valid], sim.gnss.alt[sim.gnss.valid]
    )
    assert np.abs(fixes - truth).max() < 1e-6


def test_drive_along_a_given_polyline() -> None:
    """A map polyline with sparse, cornering vertices becomes a drive: the route keeps the
    given vertices, the tunnel interval is where it was given, the approach gives open sky."""
    frame = LocalFrame(46.0, 8.0)
    en = np.array([[0, 0], [400, 0], [700, 250], [700, 700], [1100, 900], [1500, 900.0]])
    geo = frame.to_geodetic(en)
    lonlat = np.column_stack([geo[:, 1], geo[:, 0]])
    sc = polyline_scenario("given", lonlat, tunnel_intervals_m=[(600.0, 1300.0)], speed_m_s=14.0)
    sim = simulate(sc, seed=1)
    route = np.asarray(sc.route_lonlat)
    for v in np.round(lonlat, 8):
        assert np.any(np.all(np.abs(route - v) < 1e-9, axis=1))
    ((a, b),) = sim.tunnels
    assert a - sim.t0 >= 60.0
    inside = (sim.truth.t >= a) & (sim.truth.t <= b)
    driven = Route(en).project(
        sim.frame.to_enu(*sim.frame.to_geodetic(sim.truth.position[inside]).T)[:, :2]
    )
    assert driven.s.min() == pytest.approx(600.0, abs=15.0)
    assert driven.s.max() == pytest.approx(1300.0, abs=15.0)
    assert np.abs(driven.lateral).max() < 15.0
    assert np.linalg.norm(sim.truth.acceleration, axis=1).max() < 2.0
