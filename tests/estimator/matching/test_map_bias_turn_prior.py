"""The map-bias fit's rotation on a perfect track when the map is turned about a point far from
the approach (``offset.map_bias_turn_prior``, :mod:`estimator.matching.map_bias`)."""

from __future__ import annotations

import math

import numpy as np

from estimator.matching.map_bias import MapBias, learn_map_bias
from estimator.params import Params, with_values
from estimator.route import Route

GNSS_COV = np.eye(2) * 0.25
LANE = -1.75


def winding_road() -> Route:
    """A road whose approach sweeps gently left then right (2 deg each way over 800 m), then
    runs straight for 9 km (the tunnel)."""
    s = np.arange(0.0, 11000.0, 2.0)
    heading = np.radians(2.0) * np.sin(np.pi * np.clip(s / 1600.0, 0.0, 2.0))
    step = np.column_stack([np.cos(heading), np.sin(heading)]) * 2.0
    return Route(np.vstack([[0.0, 0.0], np.cumsum(step, axis=0)]))


def fit(*, turn_prior: bool, rotation_deg: float = 0.56, centre_s: float = 6000.0) -> MapBias:
    """The fit on the truth (a lane ``LANE`` right of the road over the 800 m before 1600 m),
    the map drawn turned by ``rotation_deg`` about the road at ``centre_s`` (4.4 km ahead)."""
    road = winding_road()
    a = math.radians(rotation_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    centre = road.point_at(np.array([centre_s]))[0]
    route = Route((road.xy - centre) @ rot.T + centre)
    s = np.arange(800.0, 1600.0 + 1e-9, 1.0)
    xy = road.point_at(s) + LANE * road.normal_at(s)
    params = with_values(Params(), {"offset.map_bias_turn_prior": turn_prior})
    return learn_map_bias(
        xy,
        GNSS_COV,
        route,
        s_guess=float(route.project(xy[-1:]).s[0]),
        lane_offset=LANE,
        params=params,
    )


def test_a_map_turned_far_ahead_has_its_rotation_and_lane_fitted_unbiased() -> None:
    spread = fit(turn_prior=True)
    assert spread.significant
    assert abs(math.degrees(spread.rotation) - 0.56) < 0.03
    assert abs(spread.lane - LANE) < 0.1
    # held at the local prior, the 40 m shift at the end is shrunk: the intercept's pull turns
    # the fitted rotation, and the lane takes its prior's share of the rest
    held = fit(turn_prior=False)
    assert held.significant
    assert math.degrees(held.rotation) - 0.56 > 0.1
    assert abs(held.lane - LANE) > 3.0


def test_an_unturned_map_keeps_no_rotation_and_its_lane() -> None:
    bias = fit(turn_prior=True, rotation_deg=0.0)
    assert abs(math.degrees(bias.rotation)) < 0.05
    assert abs(bias.lane - LANE) < 0.3
