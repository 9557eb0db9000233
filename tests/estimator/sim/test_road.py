"""Road geometry: exact turns, continuous curvature, smooth profiles, polylines made drivable."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from estimator.errors import ConfigError
from estimator.nav.frames import LocalFrame
from estimator.route import Route
from estimator.sim import Road, pieces_from_polyline, straight, turn
from estimator.sim.monaco import LONLAT
from estimator.sim.road import CosineSteps, gaussian_smooth, resample_polyline


@pytest.mark.parametrize("transition", ["clothoid", "cosine"])
def test_turn_angle_and_position_are_exact(transition) -> None:
    """A 90 deg left turn at R 100 m with no transitions ends 100 m left and 100 m ahead;
    with transitions the angle is still exact and curvature continuous."""
    road = Road(straight(50) + turn(90, 100, transition_m=1e-9) + straight(50))
    np.testing.assert_allclose(road.xy(road.length)[0], [150.0, 150.0], atol=1e-6)
    road = Road(straight(50) + turn(-135, 80, transition_m=40, transition=transition))
    assert road.heading(road.length)[0] == pytest.approx(np.radians(-135), abs=1e-12)
    sig = np.linspace(0, road.length, 20001)
    k = road.curvature(sig)
    assert np.abs(np.diff(k)).max() < 1e-3  # no jumps
    assert k.min() == pytest.approx(-1 / 80)
    # positions are the integral of the heading
    psi = road.heading(sig)
    xy = np.column_stack(
        [
            cumulative_trapezoid(np.cos(psi), sig, initial=0),
            cumulative_trapezoid(np.sin(psi), sig, initial=0),
        ]
    )
    np.testing.assert_allclose(road.xy(sig), xy, atol=1e-5)


def test_cosine_transition_has_continuous_curvature_rate() -> None:
    cos = Road(straight(10) + turn(60, 100, transition_m=50))
    clo = Road(straight(10) + turn(60, 100, transition_m=50, transition="clothoid"))
    at = np.array([10.0 - 1e-9, 10.0 + 1e-9])
    assert np.abs(np.diff(cos.curvature_rate(at)))[0] < 1e-9
    assert np.abs(np.diff(clo.curvature_rate(at)))[0] > 1e-4


def test_cosine_steps_value_derivative_integral() -> None:
    rng = np.random.default_rng(0)
    n = 30
    steps = CosineSteps(1.5, rng.uniform(-50, 1000, n), rng.uniform(5, 200, n), rng.normal(size=n))
    x = np.linspace(-100, 1400, 20001)
    u = np.clip((x[:, None] - steps.start) / steps.length, 0, 1)
    np.testing.assert_allclose(
        steps.value(x), 1.5 + (0.5 - 0.5 * np.cos(np.pi * u)) @ steps.delta, atol=1e-12
    )
    h = 1e-5
    np.testing.assert_allclose(
        (steps.value(x + h) - steps.value(x - h)) / (2 * h), steps.derivative(x), atol=1e-7
    )
    xi = np.linspace(0, 1400, 140001)
    np.testing.assert_allclose(
        steps.integral(xi), cumulative_trapezoid(steps.value(xi), xi, initial=0), atol=1e-5
    )


def test_speed_ramps_respect_the_acceleration_limit() -> None:
    road = Road(
        straight(500, speed_m_s=10.0)
        + straight(2500, speed_m_s=30.0)
        + straight(800, speed_m_s=8.0),
        max_accel_m_s2=1.2,
    )
    s = np.linspace(0, road.length, 100001)
    accel = road.speed.value(s) * road.speed.derivative(s)
    assert np.abs(accel).max() <= 1.2 + 1e-9
    assert np.abs(accel).max() > 0.8
    # it slows down before the slow piece starts
    assert road.speed.value(3000.0)[0] == pytest.approx(8.0)


def test_speed_changes_that_do_not_fit_stay_bounded() -> None:
    """Pieces too short for their speed changes: the changes queue up instead of adding up."""
    road = Road(
        straight(100, speed_m_s=10.0)
        + straight(300, speed_m_s=30.0)
        + straight(100, speed_m_s=8.0)
        + straight(3000),
        max_accel_m_s2=1.0,
    )
    s = np.linspace(0, road.length, 100001)
    v = road.speed.value(s)
    assert np.abs(v * road.speed.derivative(s)).max() <= 1.0 + 1e-9
    assert v.min() >= 8.0 - 1e-9 and v.max() <= 30.0 + 1e-9
    assert v[0] == 10.0 and v[-1] == pytest.approx(8.0)


def test_bad_roads_are_config_errors() -> None:
    with pytest.raises(ConfigError, match="positive length"):
        Road(straight(0.0))
    with pytest.raises(ConfigError, match="radius"):
        turn(10, 0.0)
    with pytest.raises(ConfigError, match=r"above 0\.5 m/s"):
        Road(straight(100, speed_m_s=0.0))


def test_polyline_road_follows_the_smoothed_polyline() -> None:
    """The Tunnel de Monaco's sparse OSM vertices (segments up to 512 m) become a drivable
    road within millimetres of the smoothed polyline and a few metres of the raw one."""
    ll = np.asarray(LONLAT)
    frame = LocalFrame(ll[0, 1], ll[0, 0])
    xy = frame.to_enu(ll[:, 1], ll[:, 0])[:, :2]
    pieces, start, heading0 = pieces_from_polyline(xy, smoothing_m=20.0)
    road = Road(pieces, start_xy=start, heading0=heading0)
    sig = np.linspace(0, road.length, 4000)
    p = road.xy(sig)
    dense = resample_polyline(xy, 1.0)
    smoothed = gaussian_smooth(dense, 20.0 / (Route(xy).length / (len(dense) - 1)))
    assert Route(smoothed).project(p).distance.max() < 0.01
    raw = Route(xy).project(p).distance
    assert 1.0 < raw.max() < 3.5
    assert 1 / np.abs(road.curvature(sig)).max() > 80.0
    assert road.curvature(0.0)[0] == 0.0 and road.curvature(road.length)[0] == 0.0
