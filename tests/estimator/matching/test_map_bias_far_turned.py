"""A map turned about a point kilometres into a long tunnel, lying far beyond its local prior at
the portal (``offset.map_bias_far_turned``, :mod:`estimator.matching.map_bias`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.matching.map_bias import MapBias, learn_map_bias
from estimator.params import Params, with_values
from estimator.route import Route

GNSS_COV = np.eye(2) * 0.25
LANE = -1.75
CENTRE_S = 5600.0


def bending_road() -> Route:
    """A road whose approach bends 20 deg left over its last 400 m, then runs straight for 9 km."""
    s = np.arange(0.0, 11000.0, 2.0)
    heading = np.radians(20.0) * np.clip((s - 400.0) / 400.0, 0.0, 1.0)
    step = np.column_stack([np.cos(heading), np.sin(heading)]) * 2.0
    return Route(np.vstack([[0.0, 0.0], np.cumsum(step, axis=0)]))


def fit(route_of: str, **values: object) -> MapBias:
    """The fit on the truth (a lane ``LANE`` right of the road over the 800 m before 1200 m) of
    a map drawn ``turned`` 1.8 deg about the road at ``CENTRE_S`` (4.4 km ahead, 138 m off at
    the portal) or ``parallel``, 138 m to the left of the road and not turned."""
    road = bending_road()
    centre = road.point_at(np.array([CENTRE_S]))[0]
    if route_of == "turned":
        a = math.radians(1.8)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        route = Route((road.xy - centre) @ rot.T + centre)
    else:
        route = Route(road.xy + 138.0 * road.normal_at(np.array([1200.0]))[0])
    s = np.arange(400.0, 1200.0 + 1e-9, 1.0)
    xy = road.point_at(s) + LANE * road.normal_at(s)
    return learn_map_bias(
        xy,
        GNSS_COV,
        route,
        s_guess=float(route.project(xy[-1:]).s[0]),
        lane_offset=0.0,
        params=with_values(Params(), {f"offset.{k}": v for k, v in values.items()}),
    )


def test_a_map_turned_far_ahead_is_learned_with_its_rotation_and_lane() -> None:
    bias = fit("turned")
    assert bias.significant
    assert math.degrees(bias.rotation) == pytest.approx(1.8, abs=0.05)
    assert bias.lane == pytest.approx(LANE, abs=0.3)
    # held at the local prior the fit cannot follow the route that far off, and nothing is
    # learned (the matches in the tunnel then all stay refused)
    assert not fit("turned", map_bias_far_turned=False).significant


def test_the_far_turned_fit_needs_more_than_one_linearisation_on_a_bend() -> None:
    once = fit("turned", map_bias_far_turned_passes=1)
    thrice = fit("turned")
    assert abs(math.degrees(thrice.rotation) - 1.8) < abs(math.degrees(once.rotation) - 1.8)


def test_a_parallel_road_far_off_stays_refused() -> None:
    assert not fit("parallel").significant
